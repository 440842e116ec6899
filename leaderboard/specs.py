"""The built-in report plugins' specs."""

from __future__ import annotations

from brdfbench.plugins.specs import ReportSpec

MARKDOWN = ReportSpec(
    name="markdown",
    description="leaderboard.md: accuracy beside its cost per dataset and scene, failures, convergence figures (PNG)",
    target="brdfbench_leaderboard.report:markdown_report",
    order=0,  # the leaderboard the CLI names
)

HTML = ReportSpec(
    name="html",
    description="leaderboard.html: one self-contained page: sortable tables with intervals, accuracy-against-cost "
                "plots, convergence figures, the source papers' published figures beside ours",
    target="brdfbench_leaderboard.html:html_report",
    order=10,
)
