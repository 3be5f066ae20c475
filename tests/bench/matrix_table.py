#!/usr/bin/env python3
"""The Markdown table of docs/ACCURACY.md "Through the pipeline" from the JSON lines
tests/bench/accuracy_matrix.sh writes (one line per row), with the summary statistics under it.

  tests/bench/matrix_table.py docs/accuracy-matrix.jsonl
"""
import json
import math
import sys


def row(d):
    z = [p["std_z"] for p in d["params"]]
    m = [abs(p["mean_z"]) for p in d["params"]]
    bad = [p for p in d["params"] if not p["honest"]]
    warm = "{:g} / {:g}".format(d.get("warmup", 0), max(d.get("station_warmup", -1), 0))
    outside = ", ".join("{} ({:.3f}, {:+.3f})".format(p["name"], p["std_z"], p["mean_z"])
                        for p in bad) or "—"
    return "| {} | {} | {} | {} | {} | {:.3f}–{:.3f} | {:.3f} | {:.3g} | {}/{} | {} |".format(
        d["model"], d["class"], d["protocol"], d["plan"], warm, min(z), max(z), max(m),
        d["chi2_ks_p"], d["gate_pass"], d["solved"], outside)


def main():
    rows = [json.loads(line) for line in open(sys.argv[1]) if line.strip()]
    print("| model | class | protocol | plan | warm-up (data / station) | std z, min–max | "
          "largest \\|mean z\\| | χ² p-values, KS p | gate passed | outside the criteria |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for d in rows:
        print(row(d))
    plain = [d for d in rows if not d.get("warmup", 0)]
    std = [p["std_z"] for d in plain for p in d["params"]]
    mean = [p["mean_z"] for d in plain for p in d["params"]]
    out = sum(not p["honest"] for d in plain for p in d["params"])
    avg = sum(std) / len(std)
    spread = math.sqrt(sum((s - avg) ** 2 for s in std) / (len(std) - 1))
    rms = math.sqrt(sum(x * x for x in mean) / len(mean))
    print("\nrows without warm-up: {} entries, {} outside; std z average {:.3f}, spread {:.3f}; "
          "mean z RMS {:.3f}; std z {:.3f}–{:.3f}; largest |mean z| {:.3f}; smallest KS p {:.3g}; "
          "gate {} of {}".format(len(std), out, avg, spread, rms, min(std), max(std),
                                 max(abs(x) for x in mean), min(d["chi2_ks_p"] for d in plain),
                                 sum(d["gate_pass"] for d in plain),
                                 sum(d["solved"] for d in plain)))


if __name__ == "__main__":
    main()
