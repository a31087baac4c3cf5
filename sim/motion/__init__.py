"""I-24 MOTION trajectories: the testbed's frame, and simulated runs written in its format."""
