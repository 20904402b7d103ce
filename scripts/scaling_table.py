#!/usr/bin/env python3
"""Print the scaling table of `degs sweep examples/scaling/<axis>.toml` runs.

Usage: scripts/scaling_table.py [LABEL=]CACHE [[LABEL=]CACHE ...]

Reads every CACHE/runs/*/run.json (one per experiment), and for each stage its wall
time (built, so a cached stage shows what building it cost) and peak memory, with the
scene's pixels, frames and events (the synth stage's report.json) and the warm-up's
Gaussian count (its report.json). One markdown row per experiment and cache; with
labels (e.g. `before=C1 after=C2`, the same sweeps run by two binaries) the rows of one
experiment stand together, labelled.
"""
import glob
import json
import os
import sys

STAGES = ["synth", "evflow", "gaussians", "assoc", "deform"]


def report(entry, cache):
    for p in (entry, os.path.join(cache, "cache", *entry.split(os.sep)[-2:])):
        f = os.path.join(p, "report.json")
        if os.path.exists(f):
            with open(f) as fh:
                return json.load(fh)
    return {}


def rows(cache):
    """(experiment, cells) for every finished experiment of `cache`."""
    out = []
    for rj in sorted(glob.glob(os.path.join(cache, "runs", "*", "run.json"))):
        with open(rj) as fh:
            run = json.load(fh)
        stages = {s["stage"]: s for s in run.get("stages", [])}
        if stages.get("deform", {}).get("action") not in ("cached", "ran", "rebuilt"):
            continue  # the joint training has no output (failed, pending, ...): no row
        rep = {s: report(stages[s].get("entry") or "", cache) if s in stages else {}
               for s in STAGES}
        sy = rep["synth"]
        cells = [
            str(sy.get("width", 0) * sy.get("height", 0)),
            str(sy.get("train_frames", "")),
            str(sy.get("events", "")),
            str(rep["gaussians"].get("gaussians", "")),
        ]
        cells += ["%.1f" % (stages.get(s, {}).get("built_wall_s") or 0) for s in STAGES]
        cells.append(" / ".join(
            str(round((stages.get(s, {}).get("peak_rss_kib") or 0) / 1024)) for s in STAGES))
        out.append((run.get("experiment", "?"), cells))
    return out


def main(args):
    labelled = [a.split("=", 1) if "=" in a else ("", a) for a in args]
    tables = [(label, dict(rows(cache))) for label, cache in labelled]
    names = []
    for _, t in tables:
        names += [n for n in t if n not in names]
    print("| experiment | pixels | train frames | events | Gaussians | "
          + " | ".join(f"{s} s" for s in STAGES)
          + " | peak MiB " + " / ".join(STAGES) + " |")
    print("|---" * (5 + len(STAGES) + 1) + "|")
    for name in names:
        for label, t in tables:
            if name in t:
                head = f"{name} ({label})" if label else name
                print("| " + " | ".join([head] + t[name]) + " |")


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    main(sys.argv[1:])
