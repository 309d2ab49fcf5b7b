"""Scoring a controller: the sandbox it runs in, the evaluator and the engines that play episodes."""
