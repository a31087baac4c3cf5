"""The top of the house: the server process (API with the dashboard) and the command line.

It composes the libraries below it (`app`, `dashboards`, `planner`, `sim`, `vehicle_agent`);
nothing imports it.
"""
