"""End-to-end demo: a synthetic dynamic scene, registered, and the recovered objects printed."""

import argparse
import time

import numpy as np

from mmreg import MultiModelRegistration
from mmreg._geometry import rotation_angle
from mmreg.datasets import make_scene


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--objects", type=int, default=7)
    parser.add_argument("--points", type=int, default=22395)
    parser.add_argument("--noise", type=float, default=0.03)
    parser.add_argument("--outliers", type=float, default=0.05)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)

    scene = make_scene(
        args.objects,
        args.points,
        noise=args.noise,
        outlier_fraction=args.outliers,
        random_state=args.seed,
    )
    print(
        f"scene: {len(scene.X)} correspondences, {args.objects} objects, "
        f"noise {args.noise}, {np.mean(scene.labels < 0):.0%} outliers"
    )
    start = time.perf_counter()
    est = MultiModelRegistration().fit(scene.X)
    elapsed = time.perf_counter() - start
    print(
        f"MultiModelRegistration: {est.n_clusters_} clusters in {est.n_iter_} iterations, "
        f"{elapsed * 1e3:.0f} ms (initialisation included)"
    )
    print(f"{'cluster':>7} {'size':>6} {'true object':>11} {'rot err [deg]':>13} {'trans err':>9}")
    for j in range(est.n_clusters_):
        members = est.labels_ == j
        truth = np.bincount(scene.labels[members] + 1).argmax() - 1
        if truth < 0:
            print(f"{j:>7} {members.sum():>6} {'outliers':>11}")
            continue
        rot = float(rotation_angle(est.rotations_[j], scene.rotations[truth]))
        trans = float(np.linalg.norm(est.translations_[j] - scene.translations[truth]))
        print(f"{j:>7} {members.sum():>6} {truth:>11} {rot:>13.4f} {trans:>9.4f}")
    print(f"outliers found: {np.sum(est.labels_ < 0)} (true: {np.sum(scene.labels < 0)})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
