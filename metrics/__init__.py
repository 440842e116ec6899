"""Built-in metric plugins (import name `brdfbench_metrics`).

Each metric comes as a class (streaming: update over chunks, then compute) and a
functional twin, in the style of torchmetrics, and declares its unit and direction.
"""
