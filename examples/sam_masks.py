"""SegmentAnything-like masks as the initial clusters, on FlyingThings3D-like scenes.

``make_flying_things`` renders 10 flying objects with a scene-flow network's errors;
``simulate_sam_masks`` simulates SAM's automatic masks of the first image (objects cut
into parts or merged with a neighbour, the backdrop cut into pieces, uncovered bands), in
SAM's output format: a list of dicts with a boolean H x W ``"segmentation"``.
``PrecomputedMasks`` turns masks into initial clusters through the pixel of every a-point;
with real SAM output, pass ``SamAutomaticMaskGenerator(...).generate(image)`` the same way.
Run: ``python examples/sam_masks.py`` (about 8 s).
"""

import numpy as np

from mmreg import MultiModelRegistration
from mmreg.datasets import make_flying_things, simulate_sam_masks
from mmreg.init import EuclideanClustering, PrecomputedMasks
from mmreg.metrics import iou_score, objects_found

for seed in (0, 1, 2):
    scene = make_flying_things(n_points=16384, sam_masks=False, random_state=seed)
    truth = np.where(scene.outlier_mask, -1, scene.labels)  # gross flow errors: outliers
    masks = simulate_sam_masks(scene.instance_image, random_state=seed)
    inits = {
        f"{len(masks)} SAM-like masks": PrecomputedMasks(masks, scene.pixels),
        "Euclidean, 100 clusters": EuclideanClustering(n_clusters=100),
    }
    for name, init in inits.items():
        est = MultiModelRegistration(init=init, random_state=0).fit(scene.X)
        print(
            f"scene {seed}, {name:>23}: {est.n_clusters_:2d} clusters, "
            f"IoU {iou_score(truth, est.labels_):.3f}, "
            f"objects found {objects_found(truth, est.labels_):.0%}"
        )
