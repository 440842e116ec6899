"""Leaderboard generation from the results store (import name `brdfbench_leaderboard`)."""
