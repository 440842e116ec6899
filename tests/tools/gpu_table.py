"""One table of the GPU benchmarks' figures with their targets and the device's limits.

    python tests/tools/gpu_table.py gpu-benchmarks.json [more.json ...]

Reads pytest-benchmark JSON files (`--benchmark-json`) whose benchmarks stored `value`,
`unit`, `target`, `limit` and `limit_what` in their extra_info (tests/benchmarks/
test_gpu_speed.py and the GPU cases of the other benchmark files) and prints a Markdown
table, one row per benchmark, with the device that measured it under the table.
"""

from __future__ import annotations

import json
import sys


def _fmt(x) -> str:
    if isinstance(x, (int, float)):
        return f"{x:.3g}"
    return str(x)


def rows(paths: list[str]) -> tuple[list[list[str]], set[str]]:
    out, where = [], set()
    for path in paths:
        with open(path, encoding="utf-8") as f:
            data = json.load(f)
        for bench in data.get("benchmarks", []):
            info = bench.get("extra_info", {})
            if "value" not in info:
                continue
            where.add(str(info.get("device", "?")))
            ratio = ""
            if isinstance(info.get("limit"), (int, float)) and info["limit"] > 0 and info["value"] > 0:
                ratio = f"{info['value'] / info['limit']:.3g}" if info.get("higher_is_better") else \
                    f"{info['limit'] / info['value']:.3g}"
            out.append([bench["name"], f"{_fmt(info['value'])} {info.get('unit', '')}".strip(), str(info.get("target", "")),
                        _fmt(info.get("limit", "")), ratio, str(info.get("limit_what", ""))])
    return out, where


def main(argv: list[str]) -> int:
    table, where = rows(argv)
    head = ["benchmark", "measured", "target", "limit", "share of the limit", "limit is"]
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    for r in table:
        print("| " + " | ".join(r) + " |")
    for w in sorted(where):
        print(f"\nmeasured on: {w}")
    return 0 if table else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
