"""The benchmark suite: tasks, the controller interface, seed sets, scoring and the one episode loop."""
