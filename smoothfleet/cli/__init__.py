"""`smoothfleet`: the server-side command line, one module per command group."""
