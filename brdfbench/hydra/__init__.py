"""The Hydra adapter: composes configurations and translates them into typed jobs."""
