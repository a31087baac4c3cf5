"""The Speed Planner: pure numerical stages over numpy arrays, and a thin database edge."""
