#!/usr/bin/env python3
"""Compare two event streams of the same sensor (e.g. degs' simulator against v2e).

Reads each stream from
  - .evs  (degs' columnar event file: 64-byte header `DEGSEVS\\0`, version, width,
           height, count n, hash; then columns t f64 [s], x u16, y u16, p i8 (+1/-1)), or
  - text  (one event per line `t x y p`, t in seconds, p in {0,1} or {-1,+1}; lines
           starting with '#' skipped; this is v2e's --dvs_text output and the ECD /
           rpg layout; a name ending in .gz is read through gzip).
and prints: event counts, fraction of positive events, per-pixel event-count maps
(correlation coefficient, mean |difference| / mean count, fraction of pixels differing
by more than 1 event and by more than 20 %), the same for the net (ON - OFF) map, the
event rate in time bins (correlation of the histograms), and the time offset of matched
events (the k-th event of a pixel and polarity in each stream, over the pixels where
both streams have the same number of them).

Only numpy is needed.

usage:
  compare.py A B [--size W H] [--b-t0 S] [--bin 0.01] [--frame-interval DT] [--t-range T0 T1]
             [--label-a degs] [--label-b v2e] [--json OUT.json]
"""
import argparse
import gzip
import json
import os
import struct
import sys

import numpy as np


def read_evs(path):
    with open(path, "rb") as f:
        head = f.read(64)
        if len(head) < 64 or head[:8] != b"DEGSEVS\0":
            raise ValueError(f"{path}: not a .evs file")
        version, width, height, _res, n = struct.unpack("<IIIIQ", head[8:32])
        if version != 1:
            raise ValueError(f"{path}: .evs version {version}, expected 1")
        t = np.fromfile(f, dtype="<f8", count=n)
        x = np.fromfile(f, dtype="<u2", count=n)
        y = np.fromfile(f, dtype="<u2", count=n)
        p = np.fromfile(f, dtype="i1", count=n)
    if len(p) != n:
        raise ValueError(f"{path}: truncated ({len(p)} of {n} events)")
    return dict(t=t, x=x.astype(np.int64), y=y.astype(np.int64),
                p=p.astype(np.int8), size=(width, height))


def read_text(path):
    size = None
    rows = []
    with (gzip.open(path, "rt") if path.endswith(".gz") else open(path)) as f:
        for line in f:
            s = line.strip()
            if not s:
                continue
            if s.startswith("#"):
                if "degs-events" in s:  # degs' own text header
                    kv = dict(w.split("=") for w in s.split() if "=" in w)
                    size = (int(kv["width"]), int(kv["height"]))
                continue
            rows.append(s)
    if rows:
        a = np.array(" ".join(rows).split(), dtype=np.float64)
        ncol = len(rows[0].split())
        a = a.reshape(-1, ncol)
    else:
        a = np.zeros((0, 4))
    p = a[:, 3]
    p = np.where(p > 0, 1, -1).astype(np.int8)  # {0,1} or {-1,+1} -> {-1,+1}
    return dict(t=a[:, 0], x=a[:, 1].astype(np.int64), y=a[:, 2].astype(np.int64),
                p=p, size=size)


def read_any(path):
    if path.endswith(".gz"):
        return read_text(path)
    with open(path, "rb") as f:
        magic = f.read(8)
    return read_evs(path) if magic == b"DEGSEVS\0" else read_text(path)


def corr(a, b):
    a = np.asarray(a, np.float64).ravel()
    b = np.asarray(b, np.float64).ravel()
    if a.std() == 0 or b.std() == 0:
        return float("nan")
    return float(np.corrcoef(a, b)[0, 1])


def count_map(ev, w, h, pol=None):
    m = np.ones(len(ev["t"]), bool) if pol is None else (ev["p"] == pol)
    return np.bincount(ev["y"][m] * w + ev["x"][m], minlength=w * h)[: w * h].reshape(h, w)


def map_figures(ma, mb, active_min=5):
    ma = ma.astype(np.float64)
    mb = mb.astype(np.float64)
    d = np.abs(ma - mb)
    mean = 0.5 * (ma.mean() + mb.mean())
    pair_mean = 0.5 * (ma + mb)
    active = pair_mean >= active_min
    return dict(
        corr=corr(ma, mb),
        mad_rel=float(d.mean() / mean) if mean > 0 else float("nan"),
        frac_diff_gt1=float((d > 1).mean()),
        # among pixels whose mean count (of the two) is >= active_min
        frac_active=float(active.mean()),
        frac_diff_gt20pct=float((d[active] > 0.2 * pair_mean[active]).mean())
        if active.any() else float("nan"),
    )


def matched_timing(sa, sb, w):
    """Pair the k-th event of a pixel in A with the k-th in B, over the pixels where both
    streams have the same ON sequence length and the same OFF sequence length; returns
    the statistics of t_B - t_A (seconds)."""
    dts = []
    for pol in (1, -1):
        ka, kb = [], []
        for s, k in ((sa, ka), (sb, kb)):
            m = s["p"] == pol
            pix = s["y"][m] * w + s["x"][m]
            t = s["t"][m]
            o = np.lexsort((t, pix))
            k.extend([pix[o], t[o]])
        pa, ta, pb, tb = ka[0], ka[1], kb[0], kb[1]
        n = int(max(pa.max(initial=-1), pb.max(initial=-1))) + 1
        if n == 0:
            continue
        ca = np.bincount(pa, minlength=n)
        cb = np.bincount(pb, minlength=n)
        same = (ca == cb) & (ca > 0)
        sel_a = same[pa]
        sel_b = same[pb]
        dts.append(tb[sel_b] - ta[sel_a])  # both sorted by (pixel, t): aligned
    d = np.concatenate(dts) if dts else np.zeros(0)
    if len(d) == 0:
        return dict(n_pairs=0)
    ad = np.abs(d)
    return dict(n_pairs=int(len(d)), frac_paired_a=float(len(d) / max(len(sa["t"]), 1)),
                mean_dt=float(d.mean()), median_dt=float(np.median(d)),
                median_abs_dt=float(np.median(ad)), p90_abs_dt=float(np.percentile(ad, 90)))


def rate_figures(ta, tb, edges):
    ha = np.histogram(ta, edges)[0]
    hb = np.histogram(tb, edges)[0]
    return ha, hb, corr(ha, hb), float(np.abs(ha - hb).mean() / max(0.5 * (ha.mean() + hb.mean()), 1e-12))


def figures(a, b, size, bin_s, t_range, frame_dt=None):
    w, h = size
    t0, t1 = t_range
    out = {}
    sel = {}
    for k, ev in (("a", a), ("b", b)):
        m = (ev["t"] >= t0) & (ev["t"] <= t1)
        bad = (ev["x"] < 0) | (ev["x"] >= w) | (ev["y"] < 0) | (ev["y"] >= h)
        if bad.any():
            raise ValueError(f"stream {k}: {bad.sum()} events outside {w}x{h}")
        sel[k] = {c: ev[c][m] for c in ("t", "x", "y", "p")}
    for k in ("a", "b"):
        s = sel[k]
        n = len(s["t"])
        out[f"n_{k}"] = int(n)
        out[f"pos_frac_{k}"] = float((s["p"] > 0).mean()) if n else float("nan")
        out[f"rate_per_px_hz_{k}"] = n / (w * h * (t1 - t0)) if t1 > t0 else float("nan")
    out["ratio_b_a"] = out["n_b"] / out["n_a"] if out["n_a"] else float("nan")
    ma, mb = count_map(sel["a"], w, h), count_map(sel["b"], w, h)
    out["map"] = map_figures(ma, mb)
    out["map_on"] = map_figures(count_map(sel["a"], w, h, 1), count_map(sel["b"], w, h, 1))
    out["map_off"] = map_figures(count_map(sel["a"], w, h, -1), count_map(sel["b"], w, h, -1))
    na = count_map(sel["a"], w, h, 1).astype(np.int64) - count_map(sel["a"], w, h, -1)
    nb = count_map(sel["b"], w, h, 1).astype(np.int64) - count_map(sel["b"], w, h, -1)
    out["net_corr"] = corr(na, nb)
    out["net_mad"] = float(np.abs(na - nb).mean())
    edges = np.arange(t0, t1 + 0.5 * bin_s, bin_s)
    if len(edges) < 3:
        edges = np.linspace(t0, t1, 3)
    ha = np.histogram(sel["a"]["t"], edges)[0]
    hb = np.histogram(sel["b"]["t"], edges)[0]
    out["rate_bins"] = int(len(ha))
    out["rate_corr"] = corr(ha, hb)
    out["rate_rel_mad"] = float(np.abs(ha - hb).mean() / max(0.5 * (ha.mean() + hb.mean()), 1e-12))
    out["rate_corr_on"] = corr(np.histogram(sel["a"]["t"][sel["a"]["p"] > 0], edges)[0],
                               np.histogram(sel["b"]["t"][sel["b"]["p"] > 0], edges)[0])
    # median delay of B's events against A's at the same pixel is ill-defined; report
    # the shift of the rate curves instead: lag (in bins) maximising the correlation
    lags = range(-3, 4)
    cs = [corr(ha[max(0, -l): len(ha) - max(0, l)], hb[max(0, l): len(hb) - max(0, -l)])
          for l in lags]
    out["rate_best_lag_bins"] = int(list(lags)[int(np.nanargmax(cs))]) if np.isfinite(cs).any() else 0
    if frame_dt:
        # bins holding a whole number of frame intervals, aligned on t0: a simulator that
        # places its events differently inside a frame interval (v2e: by the global
        # maximum count, not per pixel) otherwise aliases against the bin edges
        k = max(1, int(round(bin_s / frame_dt)))
        fb = k * frame_dt
        e2 = t0 + fb * np.arange(int(np.floor((t1 - t0) / fb + 1e-9)) + 1)
        e2[-1] = max(e2[-1], t1)
        _, _, c2, m2 = rate_figures(sel["a"]["t"], sel["b"]["t"], e2)
        out.update(rate_frame_bin_s=fb, rate_frame_corr=c2, rate_frame_rel_mad=m2)
    out["timing"] = matched_timing(sel["a"], sel["b"], w)
    return out


def fmt(out, la, lb):
    m, mo, mf = out["map"], out["map_on"], out["map_off"]
    rows = [
        ("events", f"{out['n_a']:,}", f"{out['n_b']:,}", f"ratio {lb}/{la} = {out['ratio_b_a']:.3f}"),
        ("events / pixel / s", f"{out['rate_per_px_hz_a']:.2f}", f"{out['rate_per_px_hz_b']:.2f}", ""),
        ("fraction positive", f"{out['pos_frac_a']:.3f}", f"{out['pos_frac_b']:.3f}", ""),
    ]
    s = [f"{'':28s} {la:>12s} {lb:>12s}"]
    for r in rows:
        s.append(f"{r[0]:28s} {r[1]:>12s} {r[2]:>12s}   {r[3]}")
    s.append("per-pixel count maps          all     ON    OFF")
    s.append(f"  correlation              {m['corr']:6.3f} {mo['corr']:6.3f} {mf['corr']:6.3f}")
    s.append(f"  mean|diff| / mean count  {m['mad_rel']:6.3f} {mo['mad_rel']:6.3f} {mf['mad_rel']:6.3f}")
    s.append(f"  frac px |diff| > 1       {m['frac_diff_gt1']:6.3f} {mo['frac_diff_gt1']:6.3f} {mf['frac_diff_gt1']:6.3f}")
    s.append(f"  frac px |diff| > 20 %    {m['frac_diff_gt20pct']:6.3f} {mo['frac_diff_gt20pct']:6.3f} {mf['frac_diff_gt20pct']:6.3f}"
             f"   (over the {m['frac_active']:.1%} of pixels with >= 5 events)")
    s.append(f"net (ON-OFF) map: correlation {out['net_corr']:.3f}, mean |diff| {out['net_mad']:.3f} events")
    s.append(f"rate in {out['rate_bins']} bins: correlation {out['rate_corr']:.4f} (ON only {out['rate_corr_on']:.4f}), "
             f"mean |diff| / mean {out['rate_rel_mad']:.3f}, best lag {out['rate_best_lag_bins']} bins")
    if "rate_frame_corr" in out:
        s.append(f"rate in bins of whole frame intervals ({out['rate_frame_bin_s']*1e3:.2f} ms): correlation "
                 f"{out['rate_frame_corr']:.4f}, mean |diff| / mean {out['rate_frame_rel_mad']:.3f}")
    tm = out["timing"]
    if tm.get("n_pairs"):
        s.append(f"matched events (k-th of a pixel and polarity, pixels with equal counts: {tm['frac_paired_a']:.1%} of A's): "
                 f"t_B - t_A mean {tm['mean_dt']*1e3:+.3f} ms, median {tm['median_dt']*1e3:+.3f} ms, "
                 f"median |.| {tm['median_abs_dt']*1e3:.3f} ms, 90th pct |.| {tm['p90_abs_dt']*1e3:.3f} ms")
    return "\n".join(s)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("a", help="first stream (.evs or text), the reference")
    ap.add_argument("b", help="second stream (.evs or text)")
    ap.add_argument("--size", nargs=2, type=int, metavar=("W", "H"),
                    help="sensor size (default: from a .evs / degs text header)")
    ap.add_argument("--a-t0", type=float, default=0.0, help="seconds added to A's times")
    ap.add_argument("--b-t0", type=float, default=0.0,
                    help="seconds added to B's times (v2e starts its clock at the first frame)")
    ap.add_argument("--bin", type=float, default=0.01, help="rate histogram bin, s (default 0.01)")
    ap.add_argument("--t-range", nargs=2, type=float, metavar=("T0", "T1"),
                    help="time window (default: from the earliest to the latest event of both)")
    ap.add_argument("--frame-interval", type=float, default=None, metavar="DT",
                    help="the frames' interval, s: also bin the rate in whole multiples of it (nearest to --bin)")
    ap.add_argument("--label-a", default=None)
    ap.add_argument("--label-b", default=None)
    ap.add_argument("--json", help="also write the figures to this JSON file")
    args = ap.parse_args(argv)

    a, b = read_any(args.a), read_any(args.b)
    a["t"] = a["t"] + args.a_t0
    b["t"] = b["t"] + args.b_t0
    size = tuple(args.size) if args.size else (a["size"] or b["size"])
    if size is None:
        ap.error("sensor size unknown: pass --size W H")
    if args.t_range:
        t_range = tuple(args.t_range)
    else:
        ts = [ev["t"] for ev in (a, b) if len(ev["t"])]
        t_range = (min(t.min() for t in ts), max(t.max() for t in ts)) if ts else (0.0, 1.0)
    la = args.label_a or os.path.basename(args.a)
    lb = args.label_b or os.path.basename(args.b)
    out = figures(a, b, size, args.bin, t_range, args.frame_interval)
    out.update(a=args.a, b=args.b, size=list(size), t_range=list(t_range), bin_s=args.bin)
    print(f"{la} = {args.a}\n{lb} = {args.b}\nsensor {size[0]}x{size[1]}, "
          f"window {t_range[0]:.4f}..{t_range[1]:.4f} s")
    print(fmt(out, la, lb))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
