"""Helpers shared by the test suites: databases, live servers, subprocess CLI."""
