"""`python -m smoothfleet.cli`: the command line without its console script."""

from smoothfleet.cli.main import main

main()
