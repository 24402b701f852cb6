"""Colour-constant images on real fixed-camera time-lapses, with held-out weights (paper §IV-A, Fig. 2(c, d); images
of §III Eq. 6–7, 10–12).

Data: ``--data DIR`` (default ``$LIGHTFAST_SHARED/data/webcam_timelapse``, else ``../shared/data/webcam_timelapse``
beside the repository), read in place. Every sub-folder with at least two images is a sequence of one fixed camera
(``--sequences`` picks some); a file name starting ``YYYYMMDD_HHMMSS`` gives the capture time (taken as UTC). The
site of a sequence (for the sun elevation of each image) comes from ``SEQUENCE/site.yaml``
(:meth:`lightfast.daylight.sun.Site.from_yaml`) if present, else from ``--site NAME=LAT,LON[,ALT]``; without one
the sun-elevation table leaves that sequence out and says so.

Protocol, per sequence: every pair of images; per image source (greyscale, F_v, F_r, the constrained peak image:
:func:`lightfast.vtr.image_sources`) ``--max-features`` features (:class:`lightfast.vtr.FeatureExtractor`, ORB by
default) matched over the whole image (:func:`lightfast.vtr.calibration.fixed_camera_matches`: nearest neighbour,
ratio 0.8, mutual); a match is correct when both keypoints lie within ``--tolerance`` px (fixed camera). Reported
per source: correct matches per pair and precision (correct / all matches). Fused (grey ∪ F_v ∪ F_r, matches found
by several sources counted once) holds every correct greyscale match by construction, so it is reported against
greyscale: the share of pairs it rescues (grey < 6 correct, fused ≥ 6: the paper's inlier minimum), the share that
falls below 6 (zero by construction: a check), and the wrong matches it adds (fused's wrong − grey's wrong, over
fused's matches), which a localizer's outlier rejection has to remove. Lighting change Δ of a pair: median |log Y_q
− log Y_r − median(log Y_q − log Y_r)| on 4× downsampled greyscale (the exposure change removed).

Held out: with two or more sequences, ``lightfast vtr calibrate``'s fit (:func:`lightfast.vtr.calibration.calibrate`,
β by ``--rule``) runs on each sequence alone, and its weights are scored on each *other* sequence next to the
printed F_v/F_r. Output: ``--output`` (default ``benchmarks/results/vtr_timelapse.md``) with ``.json`` (per-pair
counts, fits) and ``.png`` beside it, written atomically; ``--report-only`` re-renders from the ``.json``.

Usage: ``nice -n 10 .venv/bin/python benchmarks/vtr_timelapse.py [--data DIR] [--site NAME=LAT,LON[,ALT] ...]``
(the shipped webcams: about 10 min on the shared 2-core machine, 6 of them calibrating; ``--no-calibration`` skips).
"""
from __future__ import annotations

import argparse
import datetime as dt
import itertools
import json
import logging
import os
import platform
import re
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from lightfast.data.shared import shared_data_dir
from lightfast.daylight.sun import Site, sun_position
from lightfast.errors import LightfastError
from lightfast.io import write_bytes_atomic, write_text_atomic
from lightfast.vtr import ColorConstantConfig, FeatureExtractor, Features, StereoConfig, image_sources
from lightfast.vtr.calibration import (
    RULES,
    CalibrationConfig,
    CalibrationResult,
    calibrate,
    fixed_camera_matches,
    load_timelapse,
)
from lightfast.vtr.color_constant import color_constant, to_uint8

log = logging.getLogger("vtr_timelapse")

ROOT = Path(__file__).resolve().parents[1]
SOURCES = ("grey", "fv", "fr", "peak")
LABEL = {"grey": "grey", "fv": "F_v", "fr": "F_r", "peak": "peak", "fused": "fused"}
MIN_INLIERS = 6  # paper §IV-C: localization needs >= 6 matches after outlier rejection
_TIME = re.compile(r"^(\d{8}_\d{6})")


def default_data() -> Path:
    return shared_data_dir("webcam_timelapse")


def shown(path: str | Path) -> str:
    """A path as the report shows it: relative to the repository (no machine path in committed files)."""
    try:
        return os.path.relpath(Path(path).resolve(), ROOT)
    except ValueError:
        return Path(path).name


def label(key: str) -> str:
    return f"F_fit({key[4:]})" if key.startswith("fit:") else LABEL.get(key, key)


@dataclass
class TimeLapse:
    name: str
    names: list[str]
    times: list[dt.datetime | None]
    rgb: list[NDArray[np.uint8]]
    grey_small: list[NDArray[np.float32]]
    site: Site | None
    site_from: str


def parse_site(text: str) -> tuple[str, Site]:
    try:
        name, rest = text.split("=", 1)
        vals = [float(v) for v in rest.split(",")]
        if len(vals) not in (2, 3) or not name:
            raise ValueError
        return name, Site(latitude_deg=vals[0], longitude_deg=vals[1], altitude_m=vals[2] if len(vals) == 3 else 0.0)
    except (ValueError, LightfastError) as exc:
        raise argparse.ArgumentTypeError(f"expected NAME=LAT,LON[,ALT] (degrees, metres), got {text!r} "
                                         f"{exc}".rstrip()) from None


def load_sequences(data: Path, only: list[str], site_options: dict[str, Site]) -> tuple[list[TimeLapse], list[str]]:
    if not data.is_dir():
        raise SystemExit(f"vtr_timelapse: no data folder {data} (set --data or LIGHTFAST_SHARED)")
    notes: list[str] = []
    folders = sorted(p for p in data.iterdir() if p.is_dir() and (not only or p.name in only))
    missing = sorted(set(only) - {p.name for p in folders})
    if missing:
        raise SystemExit(f"vtr_timelapse: no sequence folder {', '.join(missing)} in {data}")
    unknown = sorted(set(site_options) - {p.name for p in folders})
    if unknown:
        raise SystemExit(f"vtr_timelapse: --site for {', '.join(unknown)}, which is not a sequence of {data}")
    seqs = []
    for folder in folders:
        try:
            paths, rgb = load_timelapse(folder)
        except LightfastError as exc:
            notes.append(f"`{folder.name}` left out: " + str(exc).replace(f"{folder}: ", "").replace(str(folder), "it"))
            continue
        times = []
        for p in paths:
            m = _TIME.match(p.stem)
            times.append(dt.datetime.strptime(m.group(1), "%Y%m%d_%H%M%S").replace(tzinfo=dt.UTC) if m else None)
        site, site_from = None, "none"
        if (folder / "site.yaml").is_file():
            site, site_from = Site.from_yaml(folder / "site.yaml"), f"`{folder.name}/site.yaml`"
            if folder.name in site_options:
                log.warning("%s: site.yaml found; --site %s ignored", folder.name, folder.name)
        elif folder.name in site_options:
            site, site_from = site_options[folder.name], "`--site`"
        small = [cv2.resize(g, (g.shape[1] // 4, g.shape[0] // 4), interpolation=cv2.INTER_AREA).astype(np.float32)
                 for g in (cv2.cvtColor(im, cv2.COLOR_RGB2GRAY) for im in rgb)]
        seqs.append(TimeLapse(folder.name, [p.stem for p in paths], times, rgb, small, site, site_from))
    if not seqs:
        raise SystemExit(f"vtr_timelapse: no sequence with at least 2 images in {data}")
    return seqs, notes


def lighting_change(a: NDArray[np.float32], b: NDArray[np.float32]) -> float:
    ok = (a >= 3) & (a <= 250) & (b >= 3) & (b <= 250)
    if ok.sum() < 100:
        return float("nan")
    r = np.log(b[ok]) - np.log(a[ok])
    return float(np.median(np.abs(r - np.median(r))))


def _codes(uv_a: NDArray[np.float32], uv_b: NDArray[np.float32]) -> NDArray[np.int64]:
    """One integer per match: both keypoints on a 2-px grid (images narrower than 8192 px)."""
    cells = np.clip(np.rint(np.concatenate([uv_a, uv_b], axis=1) / 2.0).astype(np.int64), 0, 4095)
    return ((cells[:, 0] * 4096 + cells[:, 1]) * 4096 + cells[:, 2]) * 4096 + cells[:, 3]


def _union(base: tuple[NDArray, NDArray], others: list[tuple[NDArray, NDArray]]) -> int:
    """Matches of ``base`` plus those of ``others`` on a 2-px cell that no ``base`` (or earlier) match covers."""
    codes = _codes(*base)
    extra = np.unique(np.concatenate([_codes(*o) for o in others]))
    return len(codes) + int(np.count_nonzero(~np.isin(extra, codes)))


def source_features(seq: TimeLapse, fits: dict[str, CalibrationResult], extractor: FeatureExtractor,
                    color: ColorConstantConfig) -> tuple[list[dict[str, Features]], dict[str, float]]:
    feats: list[dict[str, Features]] = [{} for _ in seq.rgb]
    ms: dict[str, list[float]] = {}
    for k, rgb in enumerate(seq.rgb):
        images = {n: (s.image, s.valid) for n, s in image_sources(rgb, color, SOURCES).items()}
        for train, fit in fits.items():
            cc = color_constant(rgb, fit.alpha, fit.beta, color)
            images[f"fit:{train}"] = (to_uint8(cc, color), cc.valid)
        for name, (img, valid) in images.items():
            t0 = time.perf_counter()
            feats[k][name] = extractor.detect(img, valid)
            ms.setdefault(name, []).append(1000 * (time.perf_counter() - t0))
    return feats, {k: float(np.median(v)) for k, v in ms.items()}


def match_pair(ref: dict[str, Features], qry: dict[str, Features], tol: float) -> dict[str, list[int]]:
    """[matches, correct] per source and per union: ``fused`` (grey ∪ F_v ∪ F_r) and ``grey+S`` for every other S."""
    allm: dict[str, tuple[NDArray, NDArray]] = {}
    okm: dict[str, tuple[NDArray, NDArray]] = {}
    out: dict[str, list[int]] = {}
    for name in ref:
        ua, ub, ok = fixed_camera_matches(ref[name], qry[name], tolerance_px=tol)
        allm[name], okm[name] = (ua, ub), (ua[ok], ub[ok])
        out[name] = [len(ok), int(ok.sum())]
    unions = {"fused": ["fv", "fr"], **{f"grey+{s}": [s] for s in ref if s != "grey"}}
    for key, parts in unions.items():
        out[key] = [_union(allm["grey"], [allm[s] for s in parts]), _union(okm["grey"], [okm[s] for s in parts])]
    return out


def run(args: argparse.Namespace) -> dict[str, Any]:
    sites = dict(args.site or [])
    seqs, notes = load_sequences(args.data, [s for s in args.sequences.split(",") if s], sites)
    stereo = StereoConfig(feature=args.feature, max_features=args.max_features)
    color = ColorConstantConfig(normalization=args.normalization)
    extractor = FeatureExtractor(stereo)
    fits: dict[str, CalibrationResult] = {}
    if args.no_calibration:
        notes.append("Calibration not run (`--no-calibration`).")
    elif len(seqs) < 2:
        notes.append("Calibration not run: held-out weights need a second sequence to test on.")
    else:
        cal = CalibrationConfig(rule=args.rule, max_pairs=args.calibration_pairs, tolerance_px=args.tolerance)
        for seq in seqs:
            log.info("calibrating on %s (%d images)", seq.name, len(seq.rgb))
            fits[seq.name] = calibrate(seq.rgb, cal, stereo=stereo, color=color, source=seq.name)
    data: dict[str, Any] = {"sequences": {}, "fits": {k: v.to_dict() for k, v in fits.items()}, "pairs": [],
                            "timing_ms": {}, "notes": notes}
    for seq in seqs:
        held_out = {k: v for k, v in fits.items() if k != seq.name}
        log.info("%s: features of %d images (%s)", seq.name, len(seq.rgb), ", ".join([*SOURCES, *held_out]))
        feats, ms = source_features(seq, held_out, extractor, color)
        data["timing_ms"][seq.name] = ms
        elev = [float(sun_position(seq.site, t).elevation_deg) if seq.site and t else None for t in seq.times]
        known = [t for t in seq.times if t]
        data["sequences"][seq.name] = {
            "images": len(seq.rgb), "size": f"{seq.rgb[0].shape[1]}×{seq.rgb[0].shape[0]}",
            "first": min(known).date().isoformat() if known else None,
            "last": max(known).date().isoformat() if known else None, "timed": len(known),
            "site": seq.site.to_dict() if seq.site else None, "site_from": seq.site_from,
            "names": seq.names, "sun_elevation_deg": [None if e is None else round(e, 2) for e in elev]}
        for r in range(len(seq.rgb)):
            for q in range(r + 1, len(seq.rgb)):
                er, eq = elev[r], elev[q]
                sun = None if er is None or eq is None else round(min(er, eq), 2)
                data["pairs"].append({"sequence": seq.name, "ref": r, "query": q, "sun_min": sun,
                                      "delta": round(lighting_change(seq.grey_small[r], seq.grey_small[q]), 4),
                                      "counts": match_pair(feats[r], feats[q], args.tolerance)})
    return data


# --------------------------------------------------------------------------------------------------------------
# Report


def _num(x: float, digits: int = 1) -> str:
    return "–" if not np.isfinite(x) else f"{x:.{digits}f}"


def _pct(x: float) -> str:
    return "–" if not np.isfinite(x) else f"{100 * x:.0f} %"


def _stats(group: list[dict], key: str) -> dict[str, float]:
    """Mean correct per pair, precision, share of pairs below MIN_INLIERS; against grey for unions."""
    c = np.array([p["counts"][key][1] for p in group], float)
    m = np.array([p["counts"][key][0] for p in group], float)
    g = np.array([p["counts"]["grey"][1] for p in group], float)
    gm = np.array([p["counts"]["grey"][0] for p in group], float)
    n = len(group) if group else float("nan")
    wrong_added = ((m - c).sum() - (gm - g).sum()) / m.sum() if m.sum() else float("nan")
    return {"correct": c.sum() / n, "precision": c.sum() / m.sum() if m.sum() else float("nan"),
            "below": float(np.mean(c < MIN_INLIERS)) if len(group) else float("nan"),
            "rescued": float(np.mean((g < MIN_INLIERS) & (c >= MIN_INLIERS))) if len(group) else float("nan"),
            "fell": float(np.mean((g >= MIN_INLIERS) & (c < MIN_INLIERS))) if len(group) else float("nan"),
            "gain": (c - g).sum() / n, "wrong_added": wrong_added}


def _bins(pairs: list[dict]) -> list[tuple[str, list[dict]]]:
    d = np.array([p["delta"] for p in pairs], float)
    edges = np.nanquantile(d, [0, 0.25, 0.5, 0.75, 1.0])
    names = ["Q1 (smallest)", "Q2", "Q3", "Q4 (largest)"]
    return [(f"Δ {names[k]} [{edges[k]:.2f}, {edges[k + 1]:.2f}]",
             [p for p in pairs if edges[k] <= p["delta"] < edges[k + 1] or (k == 3 and p["delta"] == edges[4])])
            for k in range(4)]


def _groups(pairs: list[dict], seqs: list[str]) -> list[tuple[str, list[dict]]]:
    return [*_bins(pairs), ("all pairs", pairs), *[(f"all `{s}`", [p for p in pairs if p["sequence"] == s])
                                                   for s in seqs]]


def _source_table(groups: list[tuple[str, list[dict]]], keys: list[str]) -> list[str]:
    lines = ["| pairs | n | " + " | ".join(label(k) for k in keys) + " |", "|---|---:|" + "---:|" * len(keys)]
    for name, g in groups:
        cells = [f"{_num((s := _stats(g, k))['correct'])} ({_pct(s['precision'])}; {_pct(s['below'])})" for k in keys]
        lines.append(f"| {name} | {len(g)} | " + " | ".join(cells) + " |")
    return lines


def _fused_table(groups: list[tuple[str, list[dict]]], key: str = "fused") -> list[str]:
    lines = [f"| pairs | n | grey < {MIN_INLIERS} | fused < {MIN_INLIERS} | rescued | fell below | correct added "
             "per pair | wrong added (share of fused matches) | precision grey → fused |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for name, g in groups:
        s, gs = _stats(g, key), _stats(g, "grey")
        lines.append(f"| {name} | {len(g)} | {_pct(gs['below'])} | {_pct(s['below'])} | {_pct(s['rescued'])} | "
                     f"{_pct(s['fell'])} | {_num(s['gain'])} | {_pct(s['wrong_added'])} | {_pct(gs['precision'])} → "
                     f"{_pct(s['precision'])} |")
    return lines


def _calibration(data: dict[str, Any], pairs: list[dict]) -> list[str]:
    fits = data["fits"]
    if not fits:
        return []
    lines = ["## Held-out colour-constant weights (`lightfast vtr calibrate`, paper §IV-A)", "",
             "Each sequence is fitted alone (`calibrate` on its images only) and its weights are tested only on the "
             "other sequence(s): a test sequence plays no part in the weights it is scored with.", "",
             "| fitted on | images | pairs scored | rule | α | β | 1 − α − β | training: F_fit | printed F_v | "
             "printed F_r | curve minimum: α (1 − α − β), score |",
             "|---|---:|---:|---|---:|---:|---:|---:|---:|---:|---|"]
    for name, f in fits.items():
        end = " (range end)" if f["on_range_end"] else ""
        pv, pr = f["printed"]["fv"], f["printed"]["fr"]
        lo = min(f["curve"], key=lambda row: row[2])
        lines.append(f"| `{name}` | {f['images']} | {f['pairs']} | {f['rule']} | {f['alpha']:+.2f}{end} | "
                     f"{f['beta']:+.3f} | {f['illuminant_exponent']:+.3f} | {f['correct_per_pair']:.2f} "
                     f"({_pct(f['precision'])}) | {pv['correct_per_pair']:.2f} ({_pct(pv['precision'])}) | "
                     f"{pr['correct_per_pair']:.2f} ({_pct(pr['precision'])}) | {lo[0]:+.2f} "
                     f"({1 - lo[0] - lo[1]:+.2f}), {lo[2]:.2f} |")
    lines += ["", "Training columns: correct matches per pair (precision) of that image alone on the sampled pairs "
              f"of the fitting sequence, α range {fits[next(iter(fits))]['alpha_range']}.", "",
              "Test (all pairs of the test sequence, and Q4: its quarter of pairs with the largest Δ; cells: correct "
              "per pair (precision; share < 6); grey ∪ S: share of pairs rescued / wrong matches added as a share of "
              "the union's matches):", "",
              "| tested on | source | weights (α, β) | all pairs | Q4 | grey ∪ S, all | grey ∪ S, Q4 |",
              "|---|---|---|---:|---:|---:|---:|"]
    printed = ColorConstantConfig()
    for test in data["sequences"]:
        tp = [p for p in pairs if p["sequence"] == test]
        tq = _bins(tp)[3][1]
        keys = ["fv", "fr", "peak", *[f"fit:{t}" for t in fits if t != test]]
        for k in keys:
            if k not in tp[0]["counts"]:
                continue
            w = ((printed.alpha_v, printed.beta_v) if k == "fv" else (printed.alpha_r, printed.beta_r)
                 if k == "fr" else (fits[k[4:]]["alpha"], fits[k[4:]]["beta"]) if k.startswith("fit:") else None)
            ws = f"{w[0]:+.2f}, {w[1]:+.3f}" if w else "Eq. 7"
            cells = []
            for g in (tp, tq):
                s = _stats(g, k)
                cells.append(f"{_num(s['correct'], 2)} ({_pct(s['precision'])}; {_pct(s['below'])})")
            for g in (tp, tq):
                s = _stats(g, f"grey+{k}")
                cells.append(f"{_pct(s['rescued'])} / {_pct(s['wrong_added'])}")
            lines.append(f"| `{test}` | {label(k)} | {ws} | " + " | ".join(cells) + " |")
        fa, fq = _stats(tp, "fused"), _stats(tq, "fused")
        lines.append(f"| `{test}` | paper's fused (grey ∪ F_v ∪ F_r) | printed | | | {_pct(fa['rescued'])} / "
                     f"{_pct(fa['wrong_added'])} | {_pct(fq['rescued'])} / {_pct(fq['wrong_added'])} |")
    lines.append("")
    for test in data["sequences"]:
        tp = [p for p in pairs if p["sequence"] == test]
        for t in (t for t in fits if t != test):
            fit, best = _stats(tp, f"fit:{t}"), max(("fv", "fr"), key=lambda k: _stats(tp, k)["correct"])
            b = _stats(tp, best)
            verdict = ("more" if fit["correct"] > b["correct"] else "fewer" if fit["correct"] < b["correct"]
                       else "as many")
            lines.append(f"- `{test}`, weights fitted on `{t}`: F_fit {fit['correct']:.2f} correct matches per pair, "
                         f"{verdict} than the better printed image ({label(best)}, {b['correct']:.2f}); grey ∪ F_fit "
                         f"rescues {_pct(_stats(tp, f'grey+fit:{t}')['rescued'])} of the pairs, grey ∪ {label(best)} "
                         f"{_pct(_stats(tp, 'grey+' + best)['rescued'])}.")
    return [*lines, ""]


def _sun_table(data: dict[str, Any], pairs: list[dict]) -> list[str]:
    with_sun = [p for p in pairs if p["sun_min"] is not None]
    lacking = [s for s, v in data["sequences"].items() if v["site"] is None or v["timed"] < v["images"]]
    head = ["## By the lower sun elevation of the two images (file-name times taken as UTC)", ""]
    why = [f"`{s}`: " + ("no site (no `site.yaml` in its folder, no `--site`)" if data["sequences"][s]["site"] is None
                         else "some file names carry no time") for s in lacking]
    if not with_sun:
        return [*head, "Skipped: " + "; ".join(why) + ".", ""]
    groups = [(name, [p for p in with_sun if lo <= p["sun_min"] < hi])
              for lo, hi, name in ((-90, 5, "< 5° (night, twilight)"), (5, 20, "5–20°"), (20, 40, "20–40°"),
                                   (40, 91, "≥ 40°"))]
    sites = "; ".join(f"`{s}`: {v['site']['latitude_deg']:.3f}°, {v['site']['longitude_deg']:.3f}°, "
                      f"{v['site']['altitude_m']:.0f} m from {v['site_from']}"
                      for s, v in data["sequences"].items() if v["site"])
    return [*head, f"Sites: {sites}." + (f" Left out: {'; '.join(why)}." if why else ""), "",
            *_source_table(groups, [*SOURCES, "fused"]), "", *_fused_table(groups), ""]


def report(data: dict[str, Any], png: bool) -> str:
    s, pairs, seqs = data["settings"], data["pairs"], list(data["sequences"])
    groups = _groups(pairs, seqs)
    rows = [f"| `{k}` | {v['images']} | {v['size']} | {v['first'] or '?'} | {v['last'] or '?'} | "
            f"{v['images'] * (v['images'] - 1) // 2} |" for k, v in data["sequences"].items()]
    q4 = _bins(pairs)[3][1]
    key = {k: _stats(q4, k) for k in [*SOURCES, "fused"]}
    lines = [
        "# Colour-constant images on real fixed-camera time-lapses (paper §IV-A, Fig. 2(c, d))", "",
        f"Data: `{s['data']}`" + (f" ({data['title']})" if data.get("title") else "") + ", read in place; "
        f"sequences (its sub-folders of images{', as chosen by `--sequences`' if data.get('chosen') else ''}): "
        f"{', '.join(f'`{k}`' for k in seqs)}.", "",
        "| sequence | images | size | first image | last image | pairs |", "|---|---:|---|---|---|---:|", *rows, "",
        *[f"- {n}" for n in data["notes"]], *([""] if data["notes"] else []),
        f"All pairs within each sequence ({len(pairs)}), {s['feature'].upper()} with {s['max_features']} features "
        f"per image and source ({s['normalization']} 8-bit mapping), whole-image matching (nearest neighbour, ratio "
        f"0.8, mutual); correct = both keypoints within {s['tolerance']:g} px (fixed cameras). Cells of the source "
        f"tables: correct matches per pair (precision = correct / all matches; share of pairs with < {MIN_INLIERS} "
        "correct). Fused = grey ∪ F_v ∪ F_r (paper Fig. 4): it keeps every correct greyscale match by construction, "
        "so it is judged by the pairs it rescues (grey < 6 correct, fused ≥ 6) and the wrong matches it adds.", "",
        f"Largest lighting changes (Q4 of Δ, {len(q4)} pairs): grey {key['grey']['correct']:.1f} correct per pair "
        f"({_pct(key['grey']['precision'])}), F_v {key['fv']['correct']:.1f} ({_pct(key['fv']['precision'])}), F_r "
        f"{key['fr']['correct']:.1f} ({_pct(key['fr']['precision'])}), peak {key['peak']['correct']:.1f} "
        f"({_pct(key['peak']['precision'])}); fused rescues {_pct(key['fused']['rescued'])} of the pairs (grey "
        f"< 6 in {_pct(key['grey']['below'])}, fused in {_pct(key['fused']['below'])}) and adds "
        f"{key['fused']['gain']:.1f} correct and {_pct(key['fused']['wrong_added'])} wrong matches (share of its "
        "matches).", "",
        "## Per source, by lighting change Δ (quartiles over all pairs)", "",
        *_source_table(groups, list(SOURCES)), "",
        "## Fused (grey ∪ F_v ∪ F_r) against greyscale", "", *_fused_table(groups), "",
        *_sun_table(data, pairs), *_calibration(data, pairs),
        "Caveats: a match counts as correct by position only (the camera is assumed fixed; jitter beyond the "
        "tolerance counts as wrong); scene changes between dates (people, vehicles, snow, wet ground, lights) "
        "count against every source alike; the cameras' spectral sensitivities, response curves and compression "
        "are unknown.", "",
        "Median feature extraction time per image, ms: " + "; ".join(
            f"`{q}`: " + ", ".join(f"{label(k)} {v:.0f}" for k, v in t.items()) for q, t in data["timing_ms"].items())
        + ".", "",
    ]
    if png:
        lines += [f"Plot: `{Path(s['output']).with_suffix('.png').name}` (left: correct matches per pair against Δ; "
                  "right: the calibration curves).", ""]
    lines += [f"Generated {data['generated']} by `{data['command']}` in {data['seconds']:.0f} s (Python "
              f"{platform.python_version()}, NumPy {np.__version__}, OpenCV {cv2.__version__}, {platform.machine()}).",
              ""]
    return "\n".join(lines)


def plot(data: dict[str, Any], path: Path) -> bool:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return False
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(13, 4.5))
    pairs = data["pairs"]
    d = np.array([p["delta"] for p in pairs], float)
    edges = np.nanquantile(d, np.linspace(0, 1, 9))
    centres = 0.5 * (edges[1:] + edges[:-1])
    colors = {"grey": "0.4", "fv": "tab:green", "fr": "tab:red", "peak": "tab:blue", "fused": "k"}
    for k, c in colors.items():
        y = np.array([p["counts"][k][1] for p in pairs], float)
        means = [y[(d >= lo) & ((d < hi) | (hi == edges[-1]))].mean() for lo, hi in itertools.pairwise(edges)]
        ax.plot(centres, np.maximum(means, 0.1), "-o", color=c, label=label(k), ms=3, lw=2.5 if k == "fused" else 1.5)
    ax.set(yscale="log", xlabel="lighting change Δ (median |Δ log brightness|, exposure removed)",
           ylabel="correct matches per pair (mean per octile of Δ)")
    ax.axhline(MIN_INLIERS, color="0.7", ls=":")
    ax.legend(fontsize=8)
    ax.grid(True, which="both", alpha=0.3)
    for name, f in data["fits"].items():
        cv = np.array(f["curve"])
        line = bx.plot(cv[:, 0], cv[:, 2], "-", label=f"fit on {name} ({f['rule']})")[0]
        for k, m in (("fv", "s"), ("fr", "^")):
            bx.plot(f["printed"][k]["alpha"], f["printed"][k]["correct_per_pair"], m, color=line.get_color(),
                    label=f"printed {label(k)} on {name}")
        bx.axvline(f["alpha"], color=line.get_color(), ls=":", lw=0.8)
    bx.set(xlabel="α", ylabel="training: correct matches per pair of F_α", title="calibration curves")
    bx.grid(True, alpha=0.3)
    if data["fits"]:
        bx.legend(fontsize=7)
    fig.tight_layout()
    tmp = path.with_name(f".{path.name}.tmp")
    fig.savefig(tmp, dpi=100, format="png")
    plt.close(fig)
    write_bytes_atomic(path, tmp.read_bytes())
    tmp.unlink()
    return True


def to_json(data: dict[str, Any]) -> str:
    """Compact: one row per pair, the counts as [matches, correct] in the order of ``count_keys``."""
    keys = sorted({k for p in data["pairs"] for k in p["counts"]})
    seqs = list(data["sequences"])
    rows = [[seqs.index(p["sequence"]), p["ref"], p["query"], p["delta"], p["sun_min"],
             *[v for k in keys for v in p["counts"].get(k, [None, None])]] for p in data["pairs"]]
    out = {k: v for k, v in data.items() if k != "pairs"}
    out.update(pair_columns=["sequence", "ref", "query", "delta", "sun_min"], count_keys=keys, pairs=rows)
    return json.dumps(out, separators=(",", ":"), ensure_ascii=False) + "\n"


def from_json(text: str) -> dict[str, Any]:
    raw = json.loads(text)
    seqs, keys = list(raw["sequences"]), raw["count_keys"]
    pairs = []
    for row in raw["pairs"]:
        counts = {k: row[5 + 2 * i: 7 + 2 * i] for i, k in enumerate(keys) if row[5 + 2 * i] is not None}
        pairs.append({"sequence": seqs[row[0]], "ref": row[1], "query": row[2], "delta": row[3], "sun_min": row[4],
                      "counts": counts})
    data = {k: v for k, v in raw.items() if k not in ("pair_columns", "count_keys", "pairs")}
    data["pairs"] = pairs
    return data


def main() -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--data", type=Path, default=default_data(),
                    help="folder of sequence folders (default: $LIGHTFAST_SHARED or ../shared, then "
                    "data/webcam_timelapse)")
    ap.add_argument("--sequences", default="", help="comma-separated sequence folders (default: all)")
    ap.add_argument("--site", type=parse_site, action="append", metavar="NAME=LAT,LON[,ALT]",
                    help="site of a sequence without SEQUENCE/site.yaml (degrees, metres); repeatable")
    ap.add_argument("--feature", default="orb", choices=("orb", "sift"))
    ap.add_argument("--normalization", default="fixed", choices=("fixed", "percentile"))
    ap.add_argument("--max-features", type=int, default=1000)
    ap.add_argument("--tolerance", type=float, default=4.0, help="correct-match radius, px")
    ap.add_argument("--rule", default="eq10", choices=RULES, help="calibration: beta from alpha (eq10 or sum1)")
    ap.add_argument("--calibration-pairs", type=int, default=200, help="calibration: pairs scored per alpha")
    ap.add_argument("--no-calibration", action="store_true", help="skip the held-out calibration")
    ap.add_argument("--output", type=Path, default=ROOT / "benchmarks" / "results" / "vtr_timelapse.md")
    ap.add_argument("--report-only", action="store_true", help="re-render the report and plot from the .json")
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
        data["chosen"] = bool(args.sequences)
        data["command"] = " ".join(["benchmarks/vtr_timelapse.py", *[
            shown(a) if Path(a).is_absolute() else a for a in sys.argv[1:]]])
        data["settings"] = {"data": shown(args.data), "feature": args.feature, "normalization": args.normalization,
                            "max_features": args.max_features, "tolerance": args.tolerance, "rule": args.rule,
                            "calibration_pairs": args.calibration_pairs, "output": shown(args.output)}
        prov = args.data / "PROVENANCE.md"
        data["title"] = prov.read_text().splitlines()[0].lstrip("# ").strip() if prov.is_file() else ""
        write_text_atomic(json_path, to_json(data))
    png = plot(data, args.output.with_suffix(".png"))
    text = report(data, png)
    write_text_atomic(args.output, text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
