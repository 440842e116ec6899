"""The run pipeline: plan (validate the whole job, list its cells) → execute (each task in a
worker process with a hard time limit) → record (the only writer of the store)."""
