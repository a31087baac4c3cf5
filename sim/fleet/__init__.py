"""The demo fleet: simulated traffic on the seed corridor and a hundred agents driving in it."""
