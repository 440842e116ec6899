"""The protocols plugins implement: representation, generator and metric of each domain."""
