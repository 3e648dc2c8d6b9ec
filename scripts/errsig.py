#!/usr/bin/env python3
"""Detected corners against a synthetic session's truth, per image.

    skinbrdf targets --detect images/*.png > det.jsonl     (in the session's directory)
    python3 scripts/errsig.py truth.json det.jsonl [--before det-before.jsonl] [--bins]

Matches each detection to the truth's target of the same id in the same image and compares
every corner with the truth's `corners_px`, split by the truth's `fully_visible`: error over the
stated sigma (worst direction), corners marked occluded, corners beyond 5 sigma. With
`--before`, also the detections per image against an earlier run (recall must not drop); with
`--bins`, the whole tags' corners by cell size (the true side over 8).
Reads both `skinbrdf targets --detect` lines and the `detect_json` example's.
"""
import json, math, statistics, sys


def load(path):
    out = {}
    for line in open(path):
        d = json.loads(line)
        dets = []
        for x in d['detections']:
            dets.append({
                'id': x['id'],
                'corners': x.get('corners_px', x.get('corners')),
                'sigma': x.get('corner_sigma_px', x.get('sigma')),
                'occluded': x.get('occluded_corners', x.get('occluded', [False] * 4)),
            })
        out[d['file']] = (dets, d.get('ms', 0.0))
    return out


def key(dets, f):
    for k in dets:
        if k.endswith(f):
            return k


def main():
    args = sys.argv[1:]
    before = None
    bins = '--bins' in args
    if bins:
        args.remove('--bins')
    if '--before' in args:
        i = args.index('--before')
        before = load(args[i + 1])
        del args[i:i + 2]
    truth = json.load(open(args[0]))
    dets = load(args[1])
    rows = []
    for im in truth['images']:
        k = key(dets, im['file'])
        if not k:
            continue
        for dd in dets[k][0]:
            tr = [x for x in im['targets'] if x['id'] == dd['id']]
            if not tr:
                continue
            tr = tr[0]
            t = tr['corners_px']
            cell = sum(math.dist(t[i], t[(i + 1) % 4]) for i in range(4)) / 32
            for q in range(4):
                e = math.dist(dd['corners'][q], tr['corners_px'][q])
                s = dd['sigma'][q]
                rows.append((tr['fully_visible'], e, s, e / s, im['file'], dd['id'], q,
                             tr['layout'], dd['occluded'][q], cell))
    for fv in [True, False]:
        r = [x for x in rows if x[0] == fv]
        if not r:
            continue
        ratios = sorted(x[3] for x in r)
        print('%-7s %5d corners: median e/s %.2f, p95 %.2f, max %.2f, >5 sigma: %d, '
              'median err %.3f px, marked occluded %d (of >0.5 px: %d/%d)' % (
                  'fully' if fv else 'partial', len(r), statistics.median(ratios),
                  ratios[int(.95 * len(ratios))], ratios[-1],
                  sum(1 for x in ratios if x > 5), statistics.median(x[1] for x in r),
                  sum(1 for x in r if x[8]), sum(1 for x in r if x[8] and x[1] > 0.5),
                  sum(1 for x in r if x[1] > 0.5)))
    if bins:
        edges = [0, 1.5, 2, 2.5, 3, 4, 6, math.inf]
        for lo, hi in zip(edges, edges[1:]):
            r = [x for x in rows if x[0] and lo <= x[9] < hi]
            if not r:
                continue
            ratios = sorted(x[3] for x in r)
            print('  whole, cell %.1f..%.1f px: %5d corners, median err %.3f px, median sigma '
                  '%.3f px, median e/s %.2f, p95 %.2f, >5 sigma: %d' % (
                      lo, hi, len(r), statistics.median(x[1] for x in r),
                      statistics.median(x[2] for x in r), statistics.median(ratios),
                      ratios[int(.95 * len(ratios))], sum(1 for v in ratios if v > 5)))
    ms = sorted(v[1] for v in dets.values())
    print('images %d, detections %d, ms/image median %.1f' % (
        len(dets), sum(len(v[0]) for v in dets.values()), statistics.median(ms)))
    if before:
        lost = gained = 0
        for f, (d, _) in dets.items():
            b = {x['id'] for x in before.get(f, ([], 0))[0]}
            a = {x['id'] for x in d}
            lost += len(b - a)
            gained += len(a - b)
            if b != a:
                print('   %s: lost %s gained %s' % (f, sorted(b - a), sorted(a - b)))
        print('detections against --before: lost %d, gained %d' % (lost, gained))
    bad = sorted([x for x in rows if x[3] > 5], key=lambda x: -x[3])
    for x in bad[:40]:
        print('  ', x[4], x[7], x[5], 'c%d' % x[6], 'fully' if x[0] else 'partial',
              'err %.2f sig %.2f ratio %.1f%s' % (x[1], x[2], x[3], ' occluded' if x[8] else ''))


main()
