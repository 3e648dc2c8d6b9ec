#!/usr/bin/env python3
"""Compares what skinbrdf's raw crate reads from real-camera files with LibRaw (rawpy) and
exiftool, field by field, and prints a markdown table (docs/ingest.md, "Real cameras against
LibRaw").

    pip install rawpy        # exiftool: apt-get install libimage-exiftool-perl
    cargo build -p skinbrdf-raw --example raw_info
    python3 scripts/peers/raw_parity.py [FILE_OR_DIR ...] [--raw-info BIN] [--out TABLE.md]
                                        [--write-expected host/raw/tests/data/real/expected.json]

Without FILE_OR_DIR: the committed subset (host/raw/tests/data/real/) and, when fetched, the
corpus in target/raw-corpus/ (scripts/corpus/fetch_raw_corpus.py).

References: LibRaw for the sensor (full size `raw_width` x `raw_height`, visible area
`width` x `height` at `left_margin`, `top_margin`, the CFA pattern at the visible origin,
`black_level_per_channel` mapped through `raw_pattern`, `white_level`) and the decoded values
(`raw_image_visible`: mean per quad position and sample photosites); exiftool (`-n`) for the
metadata (Make, Model as written, ExposureTime, ISO, FNumber, FocalLength, DateTimeOriginal).
LibRaw's own header is read with `open_file` alone, so a stripped file still gives its sizes;
values need `unpack`, which a stripped file fails. Each field is one of: `=` (agrees within its
tolerance), `≠` (both read it and disagree: both values shown), `ours: error` (the crate
refused the file, the reference read the field), `ours: none` (the crate read the file but
not the field), `n/a` (the reference has no value). A file agrees when no field is `≠`,
`ours: error` or `ours: none`.
"""
import argparse
import datetime
import json
import math
import subprocess
import sys
from pathlib import Path

import rawpy

ROOT = Path(__file__).resolve().parents[2]
COMMITTED = ROOT / "host" / "raw" / "tests" / "data" / "real"
FETCHED = ROOT / "target" / "raw-corpus"
RAW_EXTENSIONS = {
    ".dng", ".cr2", ".cr3", ".crw", ".nef", ".nrw", ".arw", ".srf", ".sr2", ".raf", ".rw2",
    ".rwl", ".raw", ".orf", ".pef", ".srw", ".mrw", ".x3f", ".iiq", ".mos", ".kdc", ".dcr",
    ".gpr", ".3fr", ".erf", ".mef",
}

# Tolerances, each with its reason.
# Black levels: LibRaw reports integers; a level the crate averages from masked photosites
# (or from a camera table) may carry a fraction.
BLACK_TOL_RAW = 0.5
# White level: both are integers from the same tags or tables.
WHITE_TOL_RAW = 0.5
# Exposure time, f-number, focal length: rationals that exiftool prints with 10 significant
# digits and the crate divides in f64; APEX-coded values (CRW) are rounded by each reader.
REL_TOL_EXPOSURE = 1e-3
# Mean decoded value per quad position: the crate's values pass through f32 normalisation and
# back, about 1e-7 relative per photosite.
REL_TOL_MEAN = 1e-5
# Sample photosites: the same round trip, a few thousandths of a raw unit at 16 bits.
ABS_TOL_SAMPLE_RAW = 0.02

EXIF_FIELDS = [
    ("make", "Make"),
    ("model", "Model"),
    ("exposure_time_s", "ExposureTime"),
    ("iso", "ISO"),
    ("f_number", "FNumber"),
    ("focal_length_mm", "FocalLength"),
    ("capture_time", "DateTimeOriginal"),
]
FIELDS = ["visible size", "sensor size", "margins", "CFA", "black", "white",
          *[f for f, _ in EXIF_FIELDS], "mean", "samples"]


def files_from(args: list[str]) -> list[Path]:
    paths = [Path(a) for a in args] or [COMMITTED, FETCHED]
    out: dict[str, Path] = {}
    for p in paths:
        items = sorted(p.iterdir()) if p.is_dir() else [p]
        for f in items:
            if f.is_file() and f.suffix.lower() in RAW_EXTENSIONS:
                out.setdefault(f.name, f)
    return [out[k] for k in sorted(out, key=str.lower)]


def libraw(path: Path) -> dict:
    """What LibRaw reads: header fields after open_file, values after unpack."""
    r = rawpy.RawPy()
    try:
        r.open_file(str(path))
    except Exception as e:  # rawpy raises one class per LibRaw error code
        return {"error": f"{type(e).__name__}: {e}"}
    s = r.sizes
    out = {
        "raw_width": s.raw_width, "raw_height": s.raw_height,
        "width": s.width, "height": s.height,
        "left_margin": s.left_margin, "top_margin": s.top_margin,
    }
    try:
        pattern = r.raw_pattern
        desc = r.color_desc.decode()
        if pattern is not None and pattern.shape == (2, 2):
            # raw_pattern is anchored at the visible area's origin.
            out["cfa"] = "".join(desc[pattern[y, x]] for y in range(2) for x in range(2))
            blacks = r.black_level_per_channel
            out["black"] = [float(blacks[pattern[y, x]]) for y in range(2) for x in range(2)]
            out["white"] = float(r.white_level)
        out["raw_type"] = str(r.raw_type)
    except Exception as e:
        out["header_error"] = f"{type(e).__name__}: {e}"
    try:
        r.unpack()
        out["unpacked"] = True
        vis = r.raw_image_visible
        if vis.ndim == 2:
            h, w = vis.shape[0] // 2 * 2, vis.shape[1] // 2 * 2
            v = vis[:h, :w].astype("float64")
            out["mean"] = [float(v[y::2, x::2].mean()) for y in range(2) for x in range(2)]
            points = [(0, 0), (1, 0), (0, 1), (1, 1), (w // 2, h // 2), (w - 1, h - 1)]
            out["samples"] = [[x, y, float(v[y, x])] for x, y in points]
    except Exception as e:
        out["unpack_error"] = f"{type(e).__name__}: {e}"
    finally:
        r.close()
    return out


def exiftool(paths: list[Path]) -> dict[str, dict]:
    tags = [f"-{t}" for _, t in EXIF_FIELDS] + ["-FileType", "-FileSize#"]
    r = subprocess.run(["exiftool", "-j", "-n", "-q", "-q", *tags, *map(str, paths)],
                       capture_output=True, text=True)
    try:
        rows = json.loads(r.stdout or "[]")
    except json.JSONDecodeError:
        rows = []
    return {Path(row["SourceFile"]).name: row for row in rows}


def ours(raw_info: str, paths: list[Path]) -> dict[str, dict]:
    out = {}
    for p in paths:
        r = subprocess.run([raw_info, str(p)], capture_output=True, text=True, timeout=300)
        try:
            out[p.name] = json.loads(r.stdout.splitlines()[0])
        except (IndexError, json.JSONDecodeError):
            out[p.name] = {"crashed": f"exit {r.returncode}: {r.stderr.strip()[-300:]}"}
    return out


def close(a, b, rel=0.0, abs_=0.0) -> bool:
    if isinstance(a, str) or isinstance(b, str):
        return str(a).strip() == str(b).strip()
    return math.isclose(float(a), float(b), rel_tol=rel, abs_tol=abs_)


def compare(o: dict, lr: dict, ex: dict) -> dict[str, tuple[str, str]]:
    """Per field: (status, detail)."""
    res: dict[str, tuple[str, str]] = {}
    ph = o.get("photosites", {})
    hd = o.get("header", {})
    md = o.get("metadata", {})
    decoded = "error" not in ph
    header = "error" not in hd

    def put(field, ref, mine, ok, refused):
        if ref is None:
            res[field] = ("n/a", "")
        elif refused:
            res[field] = ("ours: error", "")
        elif mine is None:
            res[field] = ("ours: none", f"ref {ref}")
        elif ok(mine, ref):
            res[field] = ("=", f"{ref}")
        else:
            res[field] = ("≠", f"ours {mine}, ref {ref}")

    lr_ok = "error" not in lr
    ref_vis = (lr["width"] // 2 * 2, lr["height"] // 2 * 2) if lr_ok else None
    mine_vis = ((ph["width_px"], ph["height_px"]) if decoded else
                (2 * hd["superpixel_width_px"], 2 * hd["superpixel_height_px"]) if header else None)
    put("visible size", ref_vis, mine_vis, lambda a, b: a == b, not (decoded or header))
    put("sensor size", (lr["raw_width"], lr["raw_height"]) if lr_ok else None,
        (ph["sensor_width_px"], ph["sensor_height_px"]) if decoded else None,
        lambda a, b: a == b, not decoded)
    put("margins", (lr["left_margin"], lr["top_margin"]) if lr_ok else None,
        (ph["active_left_px"], ph["active_top_px"]) if decoded else None,
        lambda a, b: a == b, not decoded)
    mine_cfa = ph.get("cfa") if decoded else hd.get("cfa") if header else None
    put("CFA", lr.get("cfa"), mine_cfa, lambda a, b: a == b, not (decoded or header))
    put("black", lr.get("black"), ph.get("black_levels") if decoded else None,
        lambda a, b: all(close(x, y, abs_=BLACK_TOL_RAW) for x, y in zip(a, b)), not decoded)
    put("white", lr.get("white"), ph.get("white_level") if decoded else None,
        lambda a, b: close(a, b, abs_=WHITE_TOL_RAW), not decoded)
    md_ok = "error" not in md
    for field, tag in EXIF_FIELDS:
        ref = ex.get(tag)
        if isinstance(ref, str):
            ref = ref.strip() or None
        numeric = field in ("exposure_time_s", "f_number", "focal_length_mm")
        put(field, ref, md.get(field) if md_ok else None,
            (lambda a, b: close(a, b, rel=REL_TOL_EXPOSURE)) if numeric else
            (lambda a, b: close(a, b)), not md_ok)
    put("mean", lr.get("mean"), ph.get("mean_raw_per_position") if decoded else None,
        lambda a, b: all(x is not None and close(x, y, rel=REL_TOL_MEAN) for x, y in zip(a, b)),
        not decoded)
    put("samples", lr.get("samples"), ph.get("samples_raw") if decoded else None,
        lambda a, b: len(a) == len(b) and all(p[:2] == q[:2] and close(p[2], q[2], abs_=ABS_TOL_SAMPLE_RAW)
                                              for p, q in zip(a, b)), not decoded)
    return res


def first_error(o: dict) -> str:
    for key in ("crashed",):
        if key in o:
            return f"crashed: {o[key]}"
    for key in ("kind", "metadata", "header", "photosites"):
        v = o.get(key)
        if isinstance(v, dict) and "error" in v:
            return v["error"]
    return ""


def short_error(text: str, path: Path) -> str:
    """An error without the file's directory, on one line, for the table."""
    for form in (str(path.resolve()), str(path)):
        text = text.replace(form, path.name)
    i = text.find(path.name)
    text = text[i:] if i >= 0 else text
    return text.splitlines()[0].replace("|", "\\|") if text else ""


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("files", nargs="*")
    ap.add_argument("--raw-info", default=None, help="the raw_info example binary")
    ap.add_argument("--out", type=Path, default=None, help="write the markdown table here too")
    ap.add_argument("--write-expected", type=Path, default=None,
                    help="write the references (LibRaw, exiftool) per file as JSON")
    args = ap.parse_args()
    paths = files_from(args.files)
    if not paths:
        print("raw_parity: no raw files found", file=sys.stderr)
        return 2
    raw_info = args.raw_info or str(
        Path(__import__("os").environ.get("CARGO_TARGET_DIR", ROOT / "target")) / "debug" / "examples" / "raw_info")
    mine = ours(raw_info, paths)
    exif = exiftool(paths)
    refs = {p.name: libraw(p) for p in paths}
    rows, counts, agree = [], {f: {} for f in FIELDS}, 0
    expected = {}
    for p in paths:
        o, lr, ex = mine[p.name], refs[p.name], exif.get(p.name, {})
        res = compare(o, lr, ex)
        for f, (st, _) in res.items():
            counts[f][st] = counts[f].get(st, 0) + 1
        ok = all(st in ("=", "n/a") for st, _ in res.values())
        agree += ok
        camera = f"{ex.get('Make', '?')} {ex.get('Model', '?')}".strip()
        lr_cell = ("cannot open" if "error" in lr else
                   "header only" if not lr.get("unpacked") else
                   "reads" if "mean" in lr else "reads (no CFA)")
        cells = []
        for f in FIELDS:
            st, detail = res[f]
            cells.append(st if st in ("=", "n/a", "ours: error") else f"{st} ({detail})")
        err = short_error(first_error(o), p)
        rows.append(f"| `{p.name}` | {camera} | {p.stat().st_size:,} | {lr_cell} | "
                    + " | ".join(cells) + f" | {'yes' if ok else 'no'} | {err} |")
        expected[p.name] = {
            "libraw": lr,
            "exiftool": {f: ex.get(t) for f, t in EXIF_FIELDS},
            "exiftool_file_type": ex.get("FileType"),
        }
    now = datetime.date.today().isoformat()
    head = ("| file | camera (exiftool) | bytes | LibRaw | " + " | ".join(FIELDS)
            + " | agrees | first error of ours |\n|" + " --- |" * (len(FIELDS) + 6))
    summary = [f"{len(paths)} files, {agree} agree in every field LibRaw or exiftool reads.", "",
               "| field | = | ≠ | ours: error | ours: none | n/a |", "| --- | ---: | ---: | ---: | ---: | ---: |"]
    for f in FIELDS:
        c = counts[f]
        summary.append(f"| {f} | {c.get('=', 0)} | {c.get('≠', 0)} | {c.get('ours: error', 0)} "
                       f"| {c.get('ours: none', 0)} | {c.get('n/a', 0)} |")
    exiftool_version = subprocess.run(["exiftool", "-ver"], capture_output=True, text=True).stdout.strip()
    text = "\n".join([
        f"Run on {now}: rawpy {rawpy.__version__} (LibRaw {'.'.join(map(str, rawpy.libraw_version))}), "
        f"exiftool {exiftool_version}.", "", *summary, "", head, *rows, ""])
    print(text)
    if args.out:
        args.out.write_text(text)
    if args.write_expected:
        args.write_expected.write_text(json.dumps(
            {"about": "References per file: LibRaw (rawpy) and exiftool -n; written by scripts/peers/raw_parity.py --write-expected",
             "rawpy": rawpy.__version__, "exiftool": exiftool_version, "files": expected},
            indent=1, sort_keys=True) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
