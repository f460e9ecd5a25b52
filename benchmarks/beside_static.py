"""A walker beside a static thing (a pole, a bin, a parked car, a wall), two raw sweeps.

    python benchmarks/beside_static.py

Ray-cast streets (buildings on both sides, the road in, 1 cm range noise), one static
thing at (9, 7) and one walker (0.5 x 0.4 x 1.7 m) ``gap`` metres from it (from the
pole's or the bin's axis towards the sensor's side, from the car's or the wall's side
towards the street), walking 1.4 m/s in 8 directions; 64 beams and 2048 azimuths, 0.5 s
apart at 7 m/s (2 Hz keyframes: the walker moves 0.7 m). Within an island's radius of each
other the walker and the thing share one island, whose motion the thing decides.

Columns: walkers found (a cluster flagged ``moving_`` covers the walker with IoU >= 0.5) of
the 16 pairs (8 directions, 2 gaps), their median IoU, static clusters called moving
(clusters flagged moving whose points are mostly the static world's), and the fit's median
time (s, a shared 2-core machine). Writes benchmarks/results/beside_static.md (``--out``).
"""

import argparse
import time
import warnings
from pathlib import Path

import numpy as np

from mmreg import SweepRegistration
from mmreg.datasets._lidar import _BESIDE, _walker_beside

THINGS = tuple(_BESIDE)
GAPS = (0.6, 1.2)
HEADINGS = np.linspace(0.0, 2 * np.pi, 8, endpoint=False)


def _row(thing):
    found, ious, static_moving, seconds = 0, [], 0, []
    for heading in HEADINGS:
        for gap in GAPS:
            a, sweep, walker, static = _walker_beside(thing, heading, gap)
            start = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                est = SweepRegistration(random_state=0).fit(a, sweep=sweep)
            seconds.append(time.perf_counter() - start)
            moving = np.flatnonzero(est.moving_)
            iou = max(
                (
                    ((est.labels_ == c) & walker).sum() / ((est.labels_ == c) | walker).sum()
                    for c in moving
                ),
                default=0.0,
            )
            if iou >= 0.5:
                found += 1
                ious.append(iou)
            static_moving += sum(static[est.labels_ == c].mean() > 0.5 for c in moving)
    return {
        "thing": thing,
        "walkers found": f"{found} of {len(HEADINGS) * len(GAPS)}",
        "IoU (median, found)": f"{np.median(ious):.2f}" if ious else "-",
        "static called moving": int(static_moving),
        "s (median)": f"{np.median(seconds):.1f}",
    }


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--out", type=Path, default=Path(__file__).parent / "results" / "beside_static.md"
    )
    args = parser.parse_args(argv)
    rows = []
    for thing in THINGS:
        rows.append(_row(thing))
        print(rows[-1], flush=True)
    header = list(rows[0])
    lines = [
        "# A walker beside a static thing (benchmarks/beside_static.py)",
        "",
        "`python benchmarks/beside_static.py`: `SweepRegistration(random_state=0)` on two "
        "64-beam sweeps 0.5 s apart (7 m/s), a walker (1.4 m/s, 8 directions) "
        f"{' or '.join(str(g) for g in GAPS)} m from a static thing; found: IoU >= 0.5 "
        "with a cluster flagged moving.",
        "",
        "| " + " | ".join(header) + " |",
        "|" + "---|" * len(header),
    ]
    lines += ["| " + " | ".join(str(row[h]) for h in header) + " |" for row in rows]
    args.out.write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
