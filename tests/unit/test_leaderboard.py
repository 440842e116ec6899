import pandas as pd

from brdfbench_leaderboard import markdown, tables


def _df():
    rows = []
    for rep, err, fit in (("good", 0.1, 10.0), ("fast", 0.5, 0.01)):
        for mat in ("a", "b"):
            rows += [
                dict(representation=rep, material=mat, metric="l1_log_cos", value=err, unit="log", higher_is_better=False),
                dict(representation=rep, material=mat, metric="fit_time", value=fit, unit="s", higher_is_better=False),
                dict(representation=rep, material=mat, metric="evals_per_s", value=1e6, unit="evals/s", higher_is_better=True),
            ]
    df = pd.DataFrame(rows)
    df["status"], df["message"], df["timestamp"] = "ok", "", 1.0
    df["dataset"], df["dataset_fingerprint"], df["package_version"], df["git_sha"] = "synthetic", "fp", "0.1", "abc"
    return df


def test_ranking_follows_higher_is_better():
    summary = tables.summarize(_df())
    assert list(tables.ranking(summary, "l1_log_cos").representation) == ["good", "fast"]


def test_markdown_shows_accuracy_beside_cost():
    text = markdown.render(_df(), "store.sqlite")
    table_line = next(line for line in text.splitlines() if line.startswith("| 1 |"))
    assert "`good`" in table_line and "10" in table_line  # accuracy and its fit time on one row
    assert "fit time ↓" in text and "evals/s ↑" in text


def test_failures_listed_only_while_unresolved():
    df = _df()
    fail = df.iloc[[0]].assign(status="failed", metric="error", value=None, message="boom", material="c")
    text = markdown.render(pd.concat([df, fail]), "s")
    assert "### Failures" in text and "boom" in text
    fixed = fail.assign(status="ok", metric="l1_log_cos", value=0.2, timestamp=2.0)
    assert "### Failures" not in markdown.render(pd.concat([df, fail, fixed]), "s")


def test_empty_store():
    assert "empty" in markdown.render(pd.DataFrame(columns=_df().columns), "s")


def test_own_fit_loss_is_shown_but_never_ranked():
    df = _df()
    losses = df[df.metric == "fit_time"].assign(metric="fit_loss", value=0.003, unit="objective")
    text = markdown.render(pd.concat([df, losses], ignore_index=True), "store.sqlite")
    assert "own fit loss" in text and "0.003" in text
    assert "#### `fit_loss`" not in text  # no per-metric ranking of incomparable objectives


def test_nbrdf_release_section_says_refitting_favours_nbrdf():
    text = markdown.render(_df().assign(dataset="nbrdf_release"), "store.sqlite")
    assert "favours `nbrdf`" in text
    assert "favours" not in markdown.render(_df(), "store.sqlite")


def _with_gpu(df):
    """`fast` fitted and timed on a GPU, `good` on the CPU."""
    on_gpu = df.representation == "fast"
    return df.assign(device=on_gpu.map({True: "cuda:0", False: "cpu"}),
                     device_detail=on_gpu.map({True: "NVIDIA H200, 139.8 GiB, CC 9.0", False: "cpu"}))


def test_gpu_timings_are_marked_and_never_ranked_against_cpu_ones():
    from brdfbench_leaderboard import html, view

    df = _with_gpu(_df())
    text = markdown.render(df, "store.sqlite")
    fast = next(line for line in text.splitlines() if "`fast`" in line and line.startswith("|"))
    good = next(line for line in text.splitlines() if "`good`" in line and line.startswith("|"))
    assert "10 ms‡" in fast and "‡" not in good  # 0.01 s, in readable units
    assert "‡ computed on a GPU (NVIDIA H200)" in text
    section = next(s for s in view.build(df, "s").sections if s.kind == "table")
    assert section.accelerators == ["NVIDIA H200"]
    # the fastest fit is the GPU's, but the column's best is chosen among the CPU figures
    # only, and one CPU figure alone is no "best"
    assert [r.label for r in section.timing_peers("fit_time")] == ["good"]
    assert html._best(section, section.metrics["fit_time"]) is None
    assert html._best(section, section.metrics["l1_log_cos"]) == next(r.config_hash for r in section.rows
                                                                       if r.label == "good")
    # accuracy is not a timing: every configuration ranks
    assert [r.label for r in section.timing_peers("l1_log_cos")] == ["good", "fast"]
    page = html.render(df, "store.sqlite")
    assert "measured on a GPU (NVIDIA H200)" in page and "computed on a GPU (NVIDIA H200)" in page


def test_accelerator_is_the_model_of_a_gpu_and_nothing_for_the_cpu():
    assert tables.accelerator("cpu") == "" and tables.accelerator("") == ""
    assert tables.accelerator("NVIDIA H200, 139.8 GiB, CC 9.0, driver 580.1") == "NVIDIA H200"
