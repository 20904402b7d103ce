#!/usr/bin/env python3
"""Convert events stored in HDF5 to the .npz that degs reads (x, y, t in µs, p).

    pip install h5py hdf5plugin
    python3 scripts/h5_events_to_npz.py events.h5 events.npz

degs has no HDF5 reader: the files of DSEC and of Prophesee's tools are compressed with
HDF5 filter plugins (Blosc / Zstd for DSEC, Prophesee's ECF codec) that only the HDF5 C
library loads, and no Rust crate reads them without it. Layouts understood:

- DSEC (`events/x`, `events/y`, `events/t` in µs, `events/p` in {0, 1}, and `t_offset`
  in µs added to `t`): Blosc/Zstd, loaded by `import hdf5plugin`.
- Flat (`x`, `y`, `t`, `p` at the root or in a group `events`; `t` in µs unless
  `--t-seconds`).
- Prophesee (`CD/events`, a compound dataset with fields x, y, p, t in µs): needs the
  ECF codec (Prophesee's open-source `hdf5_ecf` plugin on HDF5_PLUGIN_PATH); without it
  h5py cannot decompress and this script says so. Prophesee's `.raw` files degs reads
  directly.

The output holds `x`, `y` as uint16, `t` as int64 µs and `p` as int8 ±1, the layout of
degs's npz reader (`scene::formats::npz`). Pass it with `--events events.npz` to
`degs import`, or name it `events.npz` beside the frames.
"""
import argparse
import os
import sys

import numpy as np


def read(path, t_seconds):
    import h5py
    try:
        import hdf5plugin  # noqa: F401  (registers Blosc, Zstd, …)
    except ImportError:
        print("note: hdf5plugin not installed; compressed DSEC files need it", file=sys.stderr)
    with h5py.File(path, "r") as f:
        if "CD" in f and "events" in f["CD"]:
            try:
                ev = f["CD/events"][:]
            except OSError as e:
                sys.exit(f"{path}: CD/events cannot be decompressed ({e}); Prophesee's ECF "
                         "codec (hdf5_ecf) must be on HDF5_PLUGIN_PATH, or convert to .raw")
            return ev["x"], ev["y"], ev["t"].astype(np.int64), ev["p"]
        g = f["events"] if "events" in f and isinstance(f["events"], h5py.Group) else f
        for k in ("x", "y", "t", "p"):
            if k not in g:
                sys.exit(f"{path}: no dataset {g.name.rstrip('/')}/{k}: not a layout this script knows")
        t = g["t"][:]
        t = np.round(t * 1e6).astype(np.int64) if t_seconds else t.astype(np.int64)
        if "t_offset" in f:
            t = t + int(f["t_offset"][()])
        return g["x"][:], g["y"][:], t, g["p"][:]


def main():
    a = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    a.add_argument("h5")
    a.add_argument("npz")
    a.add_argument("--t-seconds", action="store_true", help="flat layout: t is in seconds")
    args = a.parse_args()
    if not args.npz.endswith(".npz"):
        sys.exit(f"{args.npz}: give a name ending in .npz (numpy would add it)")
    if os.path.exists(args.npz):
        sys.exit(f"{args.npz}: exists; not overwritten (give a new file name)")
    x, y, t, p = read(args.h5, args.t_seconds)
    p = np.where(np.asarray(p) > 0, 1, -1).astype(np.int8)
    np.savez(args.npz, x=np.asarray(x, np.uint16), y=np.asarray(y, np.uint16), t=t, p=p)
    print(f"{args.npz}: {len(t)} events, t {t.min()}–{t.max()} µs")


if __name__ == "__main__":
    main()
