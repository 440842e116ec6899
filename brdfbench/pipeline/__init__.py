"""The run pipeline. `sweep` is the entry (check every job up front, run each, write the
reports, the exit status); one job is plan (validate the whole job, list its cells) →
execute (each task in a worker process with a hard time limit) → record (the only writer
of the store)."""
