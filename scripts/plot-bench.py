#!/usr/bin/env python3
"""Draws the results of `rayforge bench --json FILE` as one PNG.

Usage:
    python3 scripts/plot-bench.py results.json -o chart.png [--title TEXT]

One row per scene, two panels per row:
  left:  trace throughput, Mrays/s per ray set (primary, shadow, ao, diffuse,
         reflection; those present), one bar per structure/builder/layout,
         with Embree's low/medium/high qualities (where the file has them)
         as short horizontal line segments over each ray-set group;
  right: build time in ms per structure/builder/layout, with the Embree
         qualities as horizontal reference lines.
Records of several views of one scene are averaged. The title is --title, or
the file's machine.cpu and date. Needs matplotlib (Debian: python3-matplotlib);
draws with the non-interactive Agg backend. Exits 1 with a one-line message on
stderr when the file is missing, is not JSON, or holds no records; exits 2 on
bad usage.
"""
import argparse
import json
import sys
from collections import defaultdict

RAY_SETS = ["primary", "shadow", "ao", "diffuse", "reflection"]
QUALITIES = {"low": ":", "medium": "--", "high": "-"}  # Embree line styles
NEEDED = ("scene", "structure", "builder", "layout", "ray_set", "mrays_per_s", "build_ms")


def fail(message):
    print(f"plot-bench: error: {message}", file=sys.stderr)
    sys.exit(1)


def load(path):
    try:
        with open(path, encoding="utf-8") as f:
            doc = json.load(f)
    except OSError as e:
        fail(f"cannot read {path}: {e.strerror}")
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        fail(f"{path} is not valid JSON: {e}")
    if not isinstance(doc, dict) or "records" not in doc:
        fail(f'{path} has no "records" (not the output of `rayforge bench --json`?)')
    records = doc["records"]
    if not isinstance(records, list) or not records:
        fail(f"{path} holds no records")
    for i, r in enumerate(records):
        bad = [k for k in NEEDED if not isinstance(r, dict) or r.get(k) is None
               or (k.endswith(("_s", "_ms")) and not isinstance(r[k], (int, float)))]
        if bad:
            fail(f"record {i} in {path} lacks (numeric) {', '.join(bad)}")
    return doc, records


def mean(values):
    return sum(values) / len(values)


def summarize(records):
    """Per scene: triangles, ray sets, structures, and the averaged numbers."""
    scenes = {}
    for r in records:
        s = scenes.setdefault(r["scene"], {"triangles": r.get("triangles"), "ray_sets": [],
                                           "structures": [], "mrays": defaultdict(list),
                                           "build": defaultdict(list), "embree": defaultdict(list)})
        key = f'{r["structure"]}/{r["builder"]}/{r["layout"]}'
        for lst, item in ((s["ray_sets"], r["ray_set"]), (s["structures"], key)):
            if item not in lst:
                lst.append(item)
        s["mrays"][key, r["ray_set"]].append(r["mrays_per_s"])
        s["build"][key].append(r["build_ms"])
        for quality, e in (r.get("embree") or {}).items():
            if quality in QUALITIES and isinstance(e, dict):
                if e.get("mrays_per_s") is not None:
                    s["embree"][quality, r["ray_set"]].append(e["mrays_per_s"])
                if e.get("build_ms") is not None:
                    s["embree"][quality, "build"].append(e["build_ms"])
    for s in scenes.values():
        known = [rs for rs in RAY_SETS if rs in s["ray_sets"]]
        s["ray_sets"] = known + [rs for rs in s["ray_sets"] if rs not in RAY_SETS]
        for table in ("mrays", "build", "embree"):
            s[table] = {k: mean(v) for k, v in s[table].items()}
    return scenes


def plot(doc, scenes, out, title):
    # Imported only once the input is known good, so that errors stay one line.
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        from matplotlib.lines import Line2D
        from matplotlib.patches import Patch
    except ImportError:
        fail("matplotlib is not installed (Debian: apt install python3-matplotlib)")
    structures = list(dict.fromkeys(k for s in scenes.values() for k in s["structures"]))
    colors = {k: plt.cm.tab10(i % 10) for i, k in enumerate(structures)}
    qualities = [q for q in QUALITIES if any(q == k[0] for s in scenes.values() for k in s["embree"])]
    fig, axes = plt.subplots(len(scenes), 2, squeeze=False, figsize=(13, 1.2 + 3.6 * len(scenes)),
                             gridspec_kw={"width_ratios": [3, 1.3]})
    for (name, s), (ax_t, ax_b) in zip(scenes.items(), axes):
        tris = f' ({s["triangles"]:,} triangles)' if isinstance(s["triangles"], int) else ""
        n = len(s["structures"])
        width = 0.8 / n
        for i, key in enumerate(s["structures"]):
            xs = [g + (i - (n - 1) / 2) * width for g in range(len(s["ray_sets"]))]
            ys = [s["mrays"].get((key, rs), 0.0) for rs in s["ray_sets"]]
            bars = ax_t.bar(xs, ys, width * 0.9, color=colors[key])
            if n <= 3:  # more bars per group: the labels would only clutter
                ax_t.bar_label(bars, fmt="%.2f", fontsize=7, padding=1)
        for g, rs in enumerate(s["ray_sets"]):
            for q in qualities:
                if (q, rs) in s["embree"]:
                    ax_t.hlines(s["embree"][q, rs], g - 0.45, g + 0.45, colors="black",
                                linestyles=QUALITIES[q], linewidth=1.6)
        ax_t.set_xticks(range(len(s["ray_sets"])), s["ray_sets"])
        ax_t.set_ylabel("Mrays/s (higher is better)")
        ax_t.set_title(f"{name}{tris}: trace throughput", fontsize=10)
        ax_t.margins(y=0.15)

        builds = [s["build"][k] for k in s["structures"]]
        bars = ax_b.bar(range(n), builds, 0.6, color=[colors[k] for k in s["structures"]])
        ax_b.bar_label(bars, fmt="%.0f ms", fontsize=7, padding=1)
        refs = [(q, s["embree"][q, "build"]) for q in qualities if (q, "build") in s["embree"]]
        for q, ms in refs:
            ax_b.axhline(ms, color="black", linestyle=QUALITIES[q], linewidth=1.2)
        ax_b.set_xticks(range(n), s["structures"], rotation=20 if n > 2 else 0, ha="right" if n > 2 else "center")
        ax_b.set_xlim(-0.8, n - 0.2)
        ax_b.set_ylabel("build time, ms (lower is better)")
        ax_b.set_title(f"{name}: build time", fontsize=10)
        ax_b.margins(y=0.2)
        if refs:  # label the Embree lines on a right-hand axis, clear of the bars
            ax_r = ax_b.twinx()
            ax_r.set_ylim(ax_b.get_ylim())
            ax_r.set_yticks([ms for _, ms in refs], [f"Embree {q}\n{ms:.0f} ms" for q, ms in refs], fontsize=7)
        for ax in (ax_t, ax_b):
            ax.grid(axis="y", alpha=0.3)
            ax.set_axisbelow(True)

    handles = [Patch(color=colors[k], label=k) for k in structures]
    handles += [Line2D([], [], color="black", linestyle=QUALITIES[q], label=f"Embree {q}") for q in qualities]
    fig.legend(handles=handles, loc="upper center", ncol=min(len(handles), 8),
               bbox_to_anchor=(0.5, 1 - 0.55 / fig.get_figheight()), frameon=False, fontsize=9)
    if title is None:
        cpu = (doc.get("machine") or {}).get("cpu") or "unknown CPU"
        title = f'rayforge bench: {cpu}, {doc.get("threads", "?")} threads, {str(doc.get("date", ""))[:10]}'
    fig.suptitle(title, fontsize=12, y=1 - 0.15 / fig.get_figheight())
    fig.tight_layout(rect=(0, 0, 1, 1 - 0.7 / fig.get_figheight()))
    try:
        fig.savefig(out, dpi=110)
    except OSError as e:
        fail(f"cannot write {out}: {e.strerror}")


def main():
    parser = argparse.ArgumentParser(description="Plot `rayforge bench --json` results as a PNG.")
    parser.add_argument("results", help="JSON file written by `rayforge bench --json FILE`")
    parser.add_argument("-o", "--output", required=True, help="PNG file to write")
    parser.add_argument("--title", help="chart title (default: machine.cpu and date from the file)")
    args = parser.parse_args()
    doc, records = load(args.results)
    plot(doc, summarize(records), args.output, args.title)


if __name__ == "__main__":
    main()
