"""Real time-lapse check of the colour-constant images (paper §IV-A, Fig. 2(c, d); images of §III Eq. 6–7, 11–12).

Data: ``/work/shared/data/webcam_timelapse`` (TILDE "Webcam" / AMOS, see its PROVENANCE.md): two fixed outdoor
webcams, ``courbevoie`` (50 images) and ``chamonix`` (40 images), across days, seasons and times of day. The
camera does not move (measured: the median displacement of matched greyscale features between dates is 0 px), so a
correct match lies at the same pixel. The images are read in place; nothing is copied.

Protocol, per sequence and feature type:

* image sources (:func:`lightfast.vtr.image_sources`): greyscale (Rec. 601 luma), F_v, F_r and the constrained
  peak image (460/530/615 nm), 8-bit mapping ``fixed`` (default) and, for comparison, ``percentile``;
* features (:class:`lightfast.vtr.FeatureExtractor`, default options: 1000 per image, none within 4 px of a
  zero/saturated pixel in the colour-constant sources), ORB (the default) and SIFT;
* pairs: by default every pair of images within a sequence (2005 pairs; each image is a "reference" for the
  others, which avoids picking one arbitrary daytime reference — a single midday reference of ``courbevoie`` turned
  out to be a market day whose stalls change the scene); ``--references N`` instead matches every image against
  the N images of highest sun elevation ("daytime"). Per pair and source the features are matched over the whole
  image (:func:`lightfast.vtr.match_descriptors`: nearest neighbour, Lowe ratio 0.8, mutual) — no spatial prior,
  so the count measures how distinctive the features stay across the lighting change;
* a match is **correct** when its two keypoints lie within ``--tolerance`` px (default 4) of each other;
* **fused** = union of the correct matches of greyscale, F_v and F_r (the three sources of paper Fig. 4), with
  matches found by several sources counted once (both keypoints on the same 2-px grid cell);
* lighting change of a pair: Δ = median over pixels of |log Y_q − log Y_r − median(log Y_q − log Y_r)| on 4×
  downsampled greyscale (pixels dark or saturated in either image excluded): the typical change of local log
  brightness once the global exposure change is removed (shadows moving, sun vs overcast, night lights). Pairs are
  binned by the quartiles of Δ; a second table bins them by the sun elevation of the query image, computed with
  :func:`lightfast.daylight.sun.sun_position` assuming the file-name times are UTC (PROVENANCE says AMOS times
  are normally UTC, unverified; the night images at 02:57 and dusk at 18:57 fit UTC).

Output: a markdown report (printed and written atomically to ``--output``, default
``benchmarks/results/vtr_timelapse.md``), the per-pair numbers as ``.json`` beside it and a ``.png`` plot.

Usage: ``nice -n 10 .venv/bin/python benchmarks/vtr_timelapse.py [--features orb,sift] [--references N]``
(about 13 min for the defaults on the shared 2-core machine; ``--report-only`` re-renders from the .json).
"""
from __future__ import annotations

import argparse
import datetime as dt
import itertools
import json
import logging
import os
import platform
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from lightfast.daylight.sun import Site, sun_position
from lightfast.vtr import (
    ColorConstantConfig,
    FeatureExtractor,
    Features,
    StereoConfig,
    image_sources,
    match_descriptors,
)

log = logging.getLogger("vtr_timelapse")

DATA = Path("/work/shared/data/webcam_timelapse")
RESULTS = Path(__file__).resolve().parent / "results"
SOURCES = ("grey", "fv", "fr", "peak")
FUSED = ("grey", "fv", "fr")
LABEL = {"grey": "grey", "fv": "F_v", "fr": "F_r", "peak": "peak", "fused": "fused"}
#: Approximate sites of the webcams (named by the dataset; used only for the sun elevation of each image).
SITES = {
    "courbevoie": Site(latitude_deg=48.897, longitude_deg=2.253, altitude_m=40.0),
    "chamonix": Site(latitude_deg=45.924, longitude_deg=6.870, altitude_m=1035.0),
}
MIN_INLIERS = 6  # paper §IV-C: localization succeeds with >= 6 matches after outlier rejection


@dataclass
class Frame:
    name: str
    time_utc: dt.datetime
    sun_elevation_deg: float
    rgb: NDArray[np.uint8]
    grey_small: NDArray[np.float32]


def load_sequence(folder: Path, site: Site) -> list[Frame]:
    frames = []
    for path in sorted(folder.glob("*.png")):
        bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
        if bgr is None:
            raise RuntimeError(f"cannot read {path}")
        rgb = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
        when = dt.datetime.strptime(path.stem[:15], "%Y%m%d_%H%M%S").replace(tzinfo=dt.UTC)
        grey = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
        small = cv2.resize(grey, (grey.shape[1] // 4, grey.shape[0] // 4), interpolation=cv2.INTER_AREA)
        frames.append(
            Frame(path.stem, when, float(sun_position(site, when).elevation_deg), rgb, small.astype(np.float32))
        )
    return frames


def lighting_change(a: NDArray[np.float32], b: NDArray[np.float32]) -> tuple[float, float]:
    """(local Δ, global exposure change) in natural-log units, see the module docstring."""
    ok = (a >= 3) & (a <= 250) & (b >= 3) & (b <= 250)
    if ok.sum() < 100:
        return float("nan"), float("nan")
    r = np.log(b[ok]) - np.log(a[ok])
    m = float(np.median(r))
    return float(np.median(np.abs(r - m))), abs(m)


def extract(
    frames: Sequence[Frame], extractor: FeatureExtractor, color: ColorConstantConfig, sources: Sequence[str]
) -> tuple[list[dict[str, Features]], dict[str, list[float]]]:
    feats: list[dict[str, Features]] = []
    seconds: dict[str, list[float]] = {s: [] for s in sources}
    for f in frames:
        srcs = image_sources(f.rgb, color, tuple(sources))
        per: dict[str, Features] = {}
        for name, src in srcs.items():
            t0 = time.perf_counter()
            per[name] = extractor.detect(src.image, src.valid)
            seconds[name].append(time.perf_counter() - t0)
        feats.append(per)
    return feats, seconds


def _cell_codes(uv_a: NDArray[np.float32], uv_b: NDArray[np.float32]) -> NDArray[np.int64]:
    """One integer per match: both keypoints on a 2-px grid (images narrower than 8192 px)."""
    cells = np.clip(np.rint(np.concatenate([uv_a, uv_b], axis=1) / 2.0).astype(np.int64), 0, 4095)
    return ((cells[:, 0] * 4096 + cells[:, 1]) * 4096 + cells[:, 2]) * 4096 + cells[:, 3]


def _fused_count(grey: tuple[NDArray, NDArray], others: list[tuple[NDArray, NDArray]]) -> int:
    """Greyscale matches plus the colour-constant matches that no greyscale (or earlier) match already covers."""
    grey_codes = _cell_codes(*grey)
    other = np.unique(np.concatenate([_cell_codes(*o) for o in others])) if others else np.zeros(0, np.int64)
    return len(grey_codes) + int(np.count_nonzero(~np.isin(other, grey_codes)))


def match_pair(
    ref: dict[str, Features], query: dict[str, Features], kind: str, tolerance: float
) -> dict[str, dict[str, int]]:
    out: dict[str, dict[str, int]] = {}
    fused_all: dict[str, tuple[NDArray, NDArray]] = {}
    fused_ok: dict[str, tuple[NDArray, NDArray]] = {}
    for name in ref:
        a, b = ref[name], query[name]
        i, j, _ = match_descriptors(a.descriptors, b.descriptors, kind, ratio=0.8, mutual=True)
        ua, ub = a.uv[i], b.uv[j]
        correct = np.linalg.norm(ua - ub, axis=1) <= tolerance
        out[name] = {"matches": len(i), "correct": int(correct.sum()), "features": len(b)}
        if name in FUSED:
            fused_all[name] = (ua, ub)
            fused_ok[name] = (ua[correct], ub[correct])
    if all(s in ref for s in FUSED):
        cc = [s for s in FUSED if s != "grey"]
        out["fused"] = {
            "matches": _fused_count(fused_all["grey"], [fused_all[s] for s in cc]),
            "correct": _fused_count(fused_ok["grey"], [fused_ok[s] for s in cc]),
            "features": sum(out[s]["features"] for s in FUSED),
        }
    return out


def run(args: argparse.Namespace) -> dict:
    sequences = [s for s in args.sequences.split(",") if s]
    features = [f for f in args.features.split(",") if f]
    norms = [n for n in args.normalizations.split(",") if n]
    data: dict = {"settings": {k: str(v) if isinstance(v, Path) else v for k, v in vars(args).items()},
                  "pairs": [], "timing_ms": {}, "images": {}}
    for seq in sequences:
        frames = load_sequence(args.data / seq, SITES[seq])
        n = len(frames)
        if args.references > 0:
            order = np.argsort([-f.sun_elevation_deg for f in frames], kind="stable")
            refs = sorted(int(k) for k in order[: args.references])
            pair_list = [(r, q) for r in refs for q in range(n) if q != r]
        else:
            refs = list(range(n))
            pair_list = [(r, q) for r in range(n) for q in range(r + 1, n)]
        data["images"][seq] = [
            {"name": f.name, "time_utc": f.time_utc.isoformat(), "sun_elevation_deg": round(f.sun_elevation_deg, 2),
             "reference": k in refs}
            for k, f in enumerate(frames)
        ]
        change = {(r, q): lighting_change(frames[r].grey_small, frames[q].grey_small) for r, q in pair_list}
        for feature in features:
            extractor = FeatureExtractor(StereoConfig(feature=feature, max_features=args.max_features))
            for norm in norms:
                sources = SOURCES if norm == norms[0] else tuple(s for s in SOURCES if s != "grey")
                color = ColorConstantConfig(normalization=norm)
                log.info("%s: %s features, %s mapping, %d images", seq, feature, norm, len(frames))
                feats, seconds = extract(frames, extractor, color, sources)
                for s, secs in seconds.items():
                    data["timing_ms"].setdefault(f"{feature}/{norm}/{s}", []).extend(1000.0 * np.asarray(secs))
                if norm != norms[0]:  # greyscale does not depend on the mapping: reuse it
                    grey_feats = data.setdefault("_grey", {})[(seq, feature)]
                    for per, g in zip(feats, grey_feats, strict=True):
                        per["grey"] = g
                else:
                    data.setdefault("_grey", {})[(seq, feature)] = [per["grey"] for per in feats]
                for (r, q), (delta, glob) in change.items():
                    counts = match_pair(feats[r], feats[q], feature, args.tolerance)
                    data["pairs"].append({
                        "sequence": seq, "feature": feature, "normalization": norm,
                        "reference": frames[r].name, "query": frames[q].name,
                        "sun_elevation_reference_deg": round(frames[r].sun_elevation_deg, 2),
                        "sun_elevation_query_deg": round(frames[q].sun_elevation_deg, 2),
                        "sun_elevation_min_deg": round(min(frames[r].sun_elevation_deg,
                                                           frames[q].sun_elevation_deg), 2),
                        "delta_local": round(delta, 4), "delta_global": round(glob, 4), "counts": counts,
                    })
    data.pop("_grey", None)
    data["timing_ms"] = {k: {"median": float(np.median(v)), "mean": float(np.mean(v)), "n": len(v)}
                         for k, v in data["timing_ms"].items()}
    return data


# --------------------------------------------------------------------------------------------------------------
# Report


def _bins_delta(pairs: list[dict]) -> tuple[list[tuple[str, float, float]], NDArray[np.float64]]:
    deltas = np.array([p["delta_local"] for p in pairs])
    edges = np.nanquantile(deltas, [0.0, 0.25, 0.5, 0.75, 1.0])
    names = ["Q1 (smallest)", "Q2", "Q3", "Q4 (largest)"]
    return [(names[k], edges[k], edges[k + 1]) for k in range(4)], edges


def _in(p: dict, lo: float, hi: float, key: str, last: bool) -> bool:
    v = p[key]
    return lo <= v < hi or (last and v == hi)


def _row(label: str, group: list[dict], cols: Sequence[str]) -> str:
    n = len(group)
    cells = [label, str(n)]
    means = {}
    for c in cols:
        correct = np.array([p["counts"][c]["correct"] for p in group], float)
        matches = np.array([p["counts"][c]["matches"] for p in group], float)
        means[c] = correct.mean() if n else float("nan")
        prec = correct.sum() / matches.sum() if matches.sum() else float("nan")
        below = np.mean(correct < MIN_INLIERS) if n else float("nan")
        cells.append(f"{means[c]:.1f} ({100 * prec:.0f} %, {100 * below:.0f} %)")
    if "fused" in cols:
        g = np.array([p["counts"]["grey"]["correct"] for p in group], float)
        fz = np.array([p["counts"]["fused"]["correct"] for p in group], float)
        cells.append(f"{fz.mean() / max(g.mean(), 1e-9):.2f}")
        cells.append(f"{np.mean(fz >= g + 1):.0%}")
        cells.append(f"{np.mean(fz - g):.1f}")
    return "| " + " | ".join(cells) + " |"


def tables(data: dict) -> list[str]:
    lines: list[str] = []
    cols = (*SOURCES, "fused")
    head = ("| {bin} | pairs | " + " | ".join(LABEL[c] for c in cols)
            + " | fused / grey | pairs fused > grey | fused − grey |")
    sep = "|---|---:|" + "---:|" * (len(cols) + 3)
    combos = sorted({(p["feature"], p["normalization"]) for p in data["pairs"]},
                    key=lambda x: (x[0] != "orb", x[1] != "fixed", x))
    for feature, norm in combos:
        pairs = [p for p in data["pairs"] if p["feature"] == feature and p["normalization"] == norm]
        bins, _ = _bins_delta(pairs)
        lines += [f"### {feature.upper()}, {norm} 8-bit mapping", "",
                  "By lighting change Δ (quartiles over all pairs of both sequences):", "",
                  head.format(bin="Δ bin [range]"), sep]
        for k, (name, lo, hi) in enumerate(bins):
            group = [p for p in pairs if _in(p, lo, hi, "delta_local", k == 3)]
            lines.append(_row(f"{name} [{lo:.2f}, {hi:.2f}]", group, cols))
        lines.append(_row("all", pairs, cols))
        lines += ["", "By the lower sun elevation of the two images (file times taken as UTC):", "",
                  head.format(bin="lower sun elevation"), sep]
        for lo, hi, name in ((-90, 5, "< 5° (night, twilight)"), (5, 20, "5–20°"), (20, 40, "20–40°"),
                             (40, 91, "≥ 40°")):
            group = [p for p in pairs if lo <= p["sun_elevation_min_deg"] < hi]
            lines.append(_row(name, group, cols))
        for seq in sorted({p["sequence"] for p in pairs}):
            lines.append(_row(f"all {seq}", [p for p in pairs if p["sequence"] == seq], cols))
        lines.append("")
    return lines


def plot(data: dict, path: Path) -> bool:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return False
    combos = [c for c in (("orb", "fixed"), ("sift", "fixed"))
              if any(p["feature"] == c[0] and p["normalization"] == c[1] for p in data["pairs"])]
    fig, axes = plt.subplots(1, max(len(combos), 1), figsize=(6.5 * max(len(combos), 1), 4.5), squeeze=False)
    colors = {"grey": "0.4", "fv": "tab:green", "fr": "tab:red", "peak": "tab:blue", "fused": "k"}
    for ax, (feature, norm) in zip(axes[0], combos, strict=False):
        pairs = [p for p in data["pairs"] if p["feature"] == feature and p["normalization"] == norm]
        deltas = np.array([p["delta_local"] for p in pairs])
        edges = np.nanquantile(deltas, np.linspace(0, 1, 9))
        centers = 0.5 * (edges[1:] + edges[:-1])
        pct = [p for p in data["pairs"] if p["feature"] == feature and p["normalization"] == "percentile"]
        for group, style, suffix in ((pairs, "-o", ""), (pct, "--", " (percentile)")):
            if not group:
                continue
            deltas = np.array([p["delta_local"] for p in group])
            for c in (*SOURCES, "fused"):
                if style == "--" and c == "grey":
                    continue  # greyscale does not depend on the mapping
                y = np.array([p["counts"][c]["correct"] for p in group], float)
                means = [np.mean(y[(deltas >= lo) & ((deltas < hi) | (hi == edges[-1]) & (deltas <= hi))])
                         for lo, hi in itertools.pairwise(edges)]
                ax.plot(centers, np.maximum(means, 0.1), style, color=colors[c], label=LABEL[c] + suffix,
                        lw=2.5 if c == "fused" else 1.5, ms=4, alpha=1.0 if style == "-o" else 0.6)
        ax.set_yscale("log")
        ax.set_xlabel("lighting change Δ (median |Δ log brightness|, exposure removed)")
        ax.set_ylabel("correct matches per pair (mean over octile bin)")
        ax.set_title(f"{feature.upper()}, webcam time-lapse (solid: {norm} mapping, dashed: percentile)")
        ax.axhline(MIN_INLIERS, color="0.7", ls=":", lw=1)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}.", suffix=".png")
    os.close(fd)
    fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
    os.chmod(tmp, 0o644)
    os.replace(tmp, path)
    return True


def _summary(data: dict) -> list[str]:
    """Key numbers for the largest lighting changes (Q4 of Δ), per feature type and mapping."""
    lines = ["Largest lighting changes (Q4 of Δ), correct matches per pair, mean (pairs with < "
             f"{MIN_INLIERS} correct):", ""]
    combos = sorted({(p["feature"], p["normalization"]) for p in data["pairs"]},
                    key=lambda x: (x[0] != "orb", x[1] != "fixed", x))
    for feature, norm in combos:
        pairs = [p for p in data["pairs"] if p["feature"] == feature and p["normalization"] == norm]
        bins, _ = _bins_delta(pairs)
        _, lo, hi = bins[3]
        q4 = [p for p in pairs if _in(p, lo, hi, "delta_local", True)]

        def stat(c: str, group: list[dict] = q4) -> str:
            y = np.array([p["counts"][c]["correct"] for p in group], float)
            return f"{y.mean():.1f} ({100 * np.mean(y < MIN_INLIERS):.0f} %)"

        lines.append(f"- {feature.upper()}, {norm}: grey {stat('grey')}, F_v {stat('fv')}, F_r {stat('fr')}, "
                     f"peak {stat('peak')}, fused {stat('fused')}.")
    return [*lines, ""]


def report(data: dict, png_written: bool) -> str:
    s = data["settings"]
    n_pairs = len({(p["sequence"], p["reference"], p["query"]) for p in data["pairs"]})
    timing = data["timing_ms"]
    if s["references"] > 0:
        pairing = (f"Every image is matched against each of the {s['references']} images of highest sun elevation "
                   "of its sequence (" + "; ".join(f"{seq}: " + ", ".join(i["name"] for i in imgs if i["reference"])
                                                   for seq, imgs in data["images"].items()) + ")")
    else:
        pairing = "All image pairs within each sequence are matched"
    lines = [
        "# Colour-constant images on a real webcam time-lapse (paper §IV-A, Fig. 2(c, d))",
        "",
        f"Data: `{s['data']}` ({', '.join(f'{k}: {len(v)} images' for k, v in data['images'].items())}; fixed "
        f"webcams, JPEG-origin PNG, read in place). {pairing}: {n_pairs} pairs, over the whole image (nearest "
        f"neighbour, ratio 0.8, mutual), {s['max_features']} features per image and source. A match is correct "
        f"when both keypoints are within {s['tolerance']:g} px (fixed cameras). Fused = grey ∪ F_v ∪ F_r (the "
        "three sources of paper Fig. 4): greyscale matches plus the colour-constant matches not already found "
        "(both keypoints on the same 2-px cell).",
        "",
        "Cells: mean correct matches per pair (precision = correct / all matches; share of pairs with fewer than "
        f"{MIN_INLIERS} correct matches, the paper's localization threshold). 'pairs fused > grey': share of pairs "
        "where the fused set has more correct matches than greyscale alone; 'fused − grey': mean gain.",
        "",
        *_summary(data),
        "Caveats: the webcam images are JPEG-origin (chroma subsampled and blocky; unknown white balance, response "
        "curve, spectral sensitivities and auto exposure), while the paper used raw Bumblebee XB3 stereo images; F_v "
        "and the peak image are almost pure chroma (illuminant exponents −0.06 and 0) and show the JPEG chroma "
        "blocks. The scenes also change between dates (market stalls, vehicles, people, snow, wet ground, night "
        "lights), which no image transform undoes, and Δ mixes such changes with lighting.",
        "",
        *tables(data),
        "Feature extraction time per image (detect + describe of one 640×471 / 704×547 image, OpenCV default "
        "threads, shared and loaded 2-core machine):",
        "",
        "| feature / mapping / source | median ms | images |",
        "|---|---:|---:|",
        *[f"| {k} | {v['median']:.1f} | {v['n']} |" for k, v in sorted(timing.items())],
        "",
    ]
    if png_written:
        lines += [f"Plot: `{Path(s['output']).with_suffix('.png').name}` (correct matches against Δ; dashed: "
                  "percentile mapping).", ""]
    lines += [
        f"Generated {data['generated']} by `benchmarks/vtr_timelapse.py` in {data['seconds']:.0f} s (Python "
        f"{platform.python_version()}, NumPy {np.__version__}, OpenCV {cv2.__version__}, {platform.machine()}).",
        "",
    ]
    return "\n".join(lines)


# --------------------------------------------------------------------------------------------------------------
# Files

PAIR_COLUMNS = ("sequence", "reference", "query", "sun_elevation_reference_deg", "sun_elevation_query_deg",
                "sun_elevation_min_deg", "delta_local", "delta_global")
COUNT_COLUMNS = tuple(f"{c}_{k}" for c in (*SOURCES, "fused") for k in ("matches", "correct", "features"))


def to_json(data: dict) -> str:
    """Compact JSON: the pair table once, and per feature/mapping one row of counts per pair."""
    keys: list[tuple] = []
    index: dict[tuple, int] = {}
    counts: dict[str, list[list[int]]] = {}
    for p in data["pairs"]:
        key = tuple(p[c] for c in PAIR_COLUMNS)
        if key not in index:
            index[key] = len(keys)
            keys.append(key)
        rows = counts.setdefault(f"{p['feature']}/{p['normalization']}", [])
        rows.append([index[key]] + [p["counts"][c][k] for c in (*SOURCES, "fused")
                                    for k in ("matches", "correct", "features")])
    out = {k: v for k, v in data.items() if k != "pairs"}
    out.update(pair_columns=list(PAIR_COLUMNS), pairs=[list(k) for k in keys],
               count_columns=["pair", *COUNT_COLUMNS], counts=counts)
    return json.dumps(out, separators=(",", ":")) + "\n"


def from_json(text: str) -> dict:
    raw = json.loads(text)
    pairs = []
    for combo, rows in raw["counts"].items():
        feature, norm = combo.split("/")
        for row in rows:
            p = dict(zip(PAIR_COLUMNS, raw["pairs"][row[0]], strict=True))
            vals = iter(row[1:])
            p["counts"] = {c: {k: next(vals) for k in ("matches", "correct", "features")} for c in (*SOURCES, "fused")}
            pairs.append({**p, "feature": feature, "normalization": norm})
    data = {k: v for k, v in raw.items() if k not in ("pair_columns", "pairs", "count_columns", "counts")}
    data["pairs"] = pairs
    return data


def _atomic_write(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    with os.fdopen(fd, "w") as fh:
        fh.write(text)
    os.chmod(tmp, 0o644)  # mkstemp creates 0600
    os.replace(tmp, path)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DATA)
    ap.add_argument("--sequences", default="courbevoie,chamonix")
    ap.add_argument("--features", default="orb,sift", help="comma-separated: orb, sift")
    ap.add_argument("--normalizations", default="fixed,percentile", help="comma-separated: fixed, percentile")
    ap.add_argument("--references", type=int, default=0,
                    help="match every image against the N images of highest sun elevation; 0: all image pairs")
    ap.add_argument("--max-features", type=int, default=1000)
    ap.add_argument("--tolerance", type=float, default=4.0, help="correct-match radius, px")
    ap.add_argument("--output", type=Path, default=RESULTS / "vtr_timelapse.md")
    ap.add_argument("--report-only", action="store_true",
                    help="re-render the report and plot from the .json of --output, without matching")
    args = ap.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s")
    json_path = args.output.with_suffix(".json")
    if args.report_only:
        data = from_json(json_path.read_text())
    else:
        t0 = time.perf_counter()
        data = run(args)
        data["seconds"] = time.perf_counter() - t0
        data["generated"] = dt.datetime.now(dt.UTC).isoformat(timespec="seconds")
        _atomic_write(json_path, to_json(data))
    png_written = plot(data, args.output.with_suffix(".png"))
    text = report(data, png_written)
    _atomic_write(args.output, text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
