#!/usr/bin/env bash
# Every peer comparison, side by side with ours, in one Markdown table.
#
#   scripts/peers/run_all.sh VENV_DIR [OUT.md]
#
# 1. creates (or reuses) a Python venv in VENV_DIR and installs the peers from PyPI:
#    embreex (Embree), scipy (least_squares), scikit-misc (netlib loess, as R's loess),
#    pupil-apriltags (the AprilTag reference C library), opencv-python-headless, numpy, rawpy (LibRaw);
# 2. builds our side (release): the ray-throughput, tag-detection and fit examples;
# 3. runs each peer script in scripts/peers/ next to ours on the same inputs, back to back:
#      ray casting      embree_bench.py --compare          (same mesh, same 1.5 Mpx rays)
#      tag detection    apriltag_compare.py                 (same synthetic images, same truth)
#      least squares    peer_fit example + scipy_least_squares.py (same 1M samples, model, start)
#      loess            loess_reference.py into a scratch copy, then our parity test against it
#      DNG files        write_test_dngs example + dng_rawpy_check.py (LibRaw reads our DNGs bit for bit;
#                       decode time per 6000x4000 file: ours vs LibRaw's unpack)
# 4. writes the combined table to OUT.md (default VENV_DIR/peers.md) and prints it; the raw
#    output of every step is kept next to it (VENV_DIR/logs/).
#
# The machine may be shared: every row gives both figures from the same run and their ratio,
# and the load average before and after. Set CARGO_TARGET_DIR to reuse a build directory.
# Not run here: apriltag_reference_fixture.py (regenerates a test fixture) and
# apriltag_session_bias.py (a diagnostic of one session, not a peer comparison).
set -euo pipefail

if [[ $# -lt 1 ]]; then
    echo "usage: $0 VENV_DIR [OUT.md]" >&2
    exit 2
fi
VENV=$(mkdir -p "$1" && cd "$1" && pwd)
OUT=${2:-$VENV/peers.md}
ROOT=$(cd "$(dirname "$0")/../.." && pwd)
LOGS=$VENV/logs
mkdir -p "$LOGS"
export CARGO_TARGET_DIR=${CARGO_TARGET_DIR:-$ROOT/target}

echo "== venv $VENV" >&2
if [[ ! -x $VENV/bin/python ]]; then
    python3 -m venv "$VENV"
fi
PY=$VENV/bin/python
"$PY" -m pip install --quiet --upgrade pip
"$PY" -m pip install --quiet numpy scipy embreex scikit-misc pupil-apriltags opencv-python-headless rawpy

echo "== building our side (release)" >&2
(cd "$ROOT" && cargo build --quiet --release \
    -p skinbrdf-mesh --example ray_throughput \
    -p skinbrdf-targets --example detect_json \
    -p skinbrdf-fit --example peer_fit \
    -p skinbrdf-raw --example write_test_dngs --example decode_time)

load() { cut -d' ' -f1-3 /proc/loadavg; }
LOAD0=$(load)
ROWS=()
row() { ROWS+=("| $1 | $2 | $3 | $4 | $5 | $6 |"); }
fail() { row "$1" "failed: see logs/$2" "" "" "" ""; }

# --- ray casting: Embree ------------------------------------------------------------------------
echo "== ray casting: ours vs Embree (embreex)" >&2
if (cd "$ROOT" && "$PY" scripts/peers/embree_bench.py --compare --json) >"$LOGS/embree.txt" 2>&1; then
    read -r R1 R2 R3 < <(tail -n 1 "$LOGS/embree.txt" | "$PY" -c '
import json, sys
d = json.load(sys.stdin); o, e = d["ours"], d["embree"]; n = o["rays"]
ours = min(o["grid_s"], o["per_ray_s"]); eb = e["closest_hit_ids_best_s"]
print(f"{n / ours / 1e6:.1f}", f"{n / eb / 1e6:.1f}", f"{eb / ours:.2f}")')
    row "ray casting (${R1:-?} vs ${R2:-?} Mrays/s, same 1.5 Mpx rays, ~200k triangles)" \
        "skinbrdf-mesh (obvhs, medium build)" "Embree 4 (embreex, 1 thread)" \
        "$R1 Mrays/s" "$R2 Mrays/s" "${R3}x faster"
else
    fail "ray casting" embree.txt
fi

# --- tag detection: AprilTag C library ----------------------------------------------------------
echo "== tag detection: ours vs the AprilTag C library (pupil-apriltags)" >&2
if (cd "$ROOT" && "$PY" scripts/peers/apriltag_compare.py --images 20) >"$LOGS/apriltag.txt" 2>&1; then
    # Rows: | detector | blur | noise | found | false pos. | RMS px | median px | max px | ms |
    while IFS= read -r line; do ROWS+=("$line"); done < <("$PY" - "$LOGS/apriltag.txt" <<'EOF'
import sys
rows = {}
for l in open(sys.argv[1]):
    c = [x.strip() for x in l.strip().strip("|").split("|")]
    if len(c) == 9 and c[0] in ("apriltag-C", "skinbrdf-targets"):
        rows.setdefault((c[1], c[2]), {})[c[0]] = c
for (blur, noise), d in rows.items():
    if len(d) != 2:
        continue
    o, p = d["skinbrdf-targets"], d["apriltag-C"]
    try:
        ratio = f"{float(p[5]) / float(o[5]):.2f}x lower RMS"
    except ValueError:
        ratio = ""
    print(f"| tag corners (blur {blur} px, noise {noise}) | skinbrdf-targets | AprilTag C library "
          f"| {o[5]} px RMS, found {o[3]}, {o[8]} ms | {p[5]} px RMS, found {p[3]}, {p[8]} ms | {ratio} |")
EOF
)
else
    fail "tag detection" apriltag.txt
fi

# --- least squares: SciPy -----------------------------------------------------------------------
echo "== least squares: ours vs SciPy least_squares" >&2
SKBS=$LOGS/bench_1m.skbs
if "$CARGO_TARGET_DIR/release/examples/peer_fit" "$SKBS" >"$LOGS/ours_fit.json" 2>"$LOGS/ours_fit.err" &&
    "$PY" "$ROOT/scripts/peers/scipy_least_squares.py" "$SKBS" "$LOGS/ours_fit.json" >"$LOGS/scipy.txt" 2>&1; then
    # Its table: | run | skinbrdf (s) | SciPy lm (s) | SciPy trf (s) | lm / skinbrdf | trf / skinbrdf | final cost skinbrdf / lm / trf |
    while IFS= read -r line; do ROWS+=("$line"); done < <("$PY" - "$LOGS/scipy.txt" <<'EOF'
import sys
for l in open(sys.argv[1]):
    c = [x.strip() for x in l.strip().strip("|").split("|")]
    if len(c) != 7 or c[0] == "run" or set(c[0]) <= set("-"):
        continue
    print(f"| least squares (1 M samples, 2-lobe Lafortune): {c[0]} | skinbrdf-fit LM | SciPy least_squares lm / trf "
          f"| {c[1]} s | {c[2]} s / {c[3]} s | SciPy takes {c[4]} (lm), {c[5]} (trf) our time; final cost {c[6]} |")
EOF
)
else
    fail "least squares" scipy.txt
fi

# --- loess: netlib (scikit-misc) ----------------------------------------------------------------
echo "== loess: ours vs netlib loess (scikit-misc)" >&2
SCRATCH=$(mktemp -d)
mkdir -p "$SCRATCH/scripts/peers" "$SCRATCH/host/fit/tests/fixtures"
cp "$ROOT/scripts/peers/loess_reference.py" "$SCRATCH/scripts/peers/"
if "$PY" "$SCRATCH/scripts/peers/loess_reference.py" >"$LOGS/loess.txt" 2>&1; then
    DIFF=$("$PY" - "$SCRATCH/host/fit/tests/fixtures/loess_reference.json" \
        "$ROOT/host/fit/tests/fixtures/loess_reference.json" <<'EOF'
import json, sys
def vals(o):
    if isinstance(o, dict):
        for k in sorted(o): yield from vals(o[k])
    elif isinstance(o, list):
        for v in o: yield from vals(v)
    elif isinstance(o, (int, float)):
        yield float(o)
a, b = (list(vals(json.load(open(p)))) for p in sys.argv[1:3])
print(f"{max(abs(x - y) for x, y in zip(a, b)):.2e}" if len(a) == len(b) else "differs in shape")
EOF
)
    if (cd "$ROOT" && cargo test --quiet --release -p skinbrdf-fit loess) >"$LOGS/loess_parity.txt" 2>&1; then
        PARITY="parity test passes"
    else
        PARITY="parity test FAILS (logs/loess_parity.txt)"
    fi
    row "loess (degree 2, gaussian), 1-D and 2-D cases" "skinbrdf-fit loess" \
        "netlib dloess (scikit-misc, as R's loess)" "$PARITY" \
        "reference regenerated: max difference to the committed fixture $DIFF" ""
else
    fail "loess" loess.txt
fi
rm -rf "$SCRATCH"

# --- DNG files: LibRaw (rawpy) -------------------------------------------------------------------
echo "== DNG files: ours vs LibRaw (rawpy)" >&2
DNGS=$LOGS/dngs
rm -rf "$DNGS"
if "$CARGO_TARGET_DIR/release/examples/write_test_dngs" "$DNGS" --big >"$LOGS/dng_write.txt" 2>&1 &&
    "$PY" "$ROOT/scripts/peers/dng_rawpy_check.py" "$DNGS" >"$LOGS/dng_check.txt" 2>&1; then
    SUMMARY=$(grep -E '^[0-9]+ passed, [0-9]+ failed' "$LOGS/dng_check.txt")
    DEV=$(grep -c '^known deviation' "$LOGS/dng_check.txt" || true)
    OURS=$("$CARGO_TARGET_DIR/release/examples/decode_time" "$DNGS/big_6000x4000_14.dng" | "$PY" -c 'import json,sys; print(json.load(sys.stdin)["median_s"])')
    PEER=$("$PY" "$ROOT/scripts/peers/dng_rawpy_check.py" --time "$DNGS/big_6000x4000_14.dng" | "$PY" -c 'import json,sys; print(json.load(sys.stdin)["median_s"])')
    RATIO=$("$PY" -c "print(f'{$PEER / $OURS:.2f}x')")
    row "DNG files (our writer, 4 phases x 12/14/16 bits x even/odd active area, + 6000x4000)" \
        "skinbrdf-raw (rawler decode + superpixels)" "LibRaw (rawpy)" \
        "bit for bit: $SUMMARY ($DEV known deviations, logs/dng_check.txt)" \
        "decode 6000x4000 14-bit: ours $OURS s, LibRaw unpack $PEER s (median of 5)" "LibRaw takes $RATIO our time"
else
    fail "DNG files" dng_check.txt
fi

{
    echo "# Peers side by side"
    echo
    echo "\`scripts/peers/run_all.sh\` on $(date -u '+%Y-%m-%d %H:%M UTC'), $(nproc) cores; load average before $LOAD0, after $(load)."
    echo
    echo "| comparison | ours | peer | ours: figure | peer: figure | ratio |"
    echo "|---|---|---|---|---|---|"
    printf '%s\n' "${ROWS[@]}"
} >"$OUT"
cat "$OUT"
echo "wrote $OUT (raw output in $LOGS)" >&2
