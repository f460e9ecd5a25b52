"""Quick start: find the moving objects of a synthetic scene and score them.

Run: ``python examples/quick_start.py [PICTURE.png]`` (about 2 s). A picture of the
result is written when a file name is given.
"""

import sys

import numpy as np

from mmreg import MultiModelRegistration
from mmreg.datasets import make_scene
from mmreg.metrics import iou_score, objects_found, rotation_error, translation_error

# 5 objects, Gaussian noise of 1 cm on the b-points and 5 % outliers.
scene = make_scene(n_objects=5, n_points=5000, noise=0.01, outlier_fraction=0.05, random_state=0)
X = np.hstack([scene.a, scene.b])  # (n, 6): a_i and its correspondence b_i

est = MultiModelRegistration(random_state=0).fit(X)
print(f"{est.n_clusters_} clusters in {est.n_iter_} iterations, {est.outlier_mask_.sum()} outliers")
for j in range(est.n_clusters_):
    angle = np.degrees(np.arccos(np.clip((np.trace(est.rotations_[j]) - 1) / 2, -1, 1)))
    print(
        f"  cluster {j}: {np.sum(est.labels_ == j)} points, rotation {angle:.1f} deg, "
        f"translation {np.round(est.translations_[j], 2)}"
    )

truth = (scene.rotations, scene.translations)
fitted = (est.rotations_, est.translations_)
print(f"IoU {iou_score(scene.labels, est.labels_):.3f}")
print(f"objects found {objects_found(scene.labels, est.labels_):.0%}")
print(f"rotation error {rotation_error(scene.labels, est.labels_, truth, fitted):.3f} deg")
print(f"translation error {translation_error(scene.labels, est.labels_, truth, fitted):.4f} m")

if len(sys.argv) > 1:  # a picture: a-points by cluster and an arrow per motion
    from matplotlib.figure import Figure

    from mmreg.plotting import plot_clusters

    fig = Figure(figsize=(8, 7), layout="constrained")
    ax = fig.add_subplot(projection="3d")
    plot_clusters(scene.a, est.labels_, ax=ax, motions=fitted, title="clusters found")
    fig.savefig(sys.argv[1], dpi=100)
    print(f"written: {sys.argv[1]}")
