"""Speed plans: the planner's schedule and commands, and the API serving its plans."""
