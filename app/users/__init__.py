"""Dashboard users: passwords, roles, login throttling."""
