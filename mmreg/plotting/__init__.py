"""Pictures of a registration: clusters in 3-D, from above, through the camera, side by side.

Every function draws the a-points coloured by cluster with one colour scheme: the largest
cluster (the static background, in a driving scene) in a neutral sand colour, the other
clusters in a qualitative palette by decreasing size, the outliers (label ``-1``) small
and grey. Functions draw into the ``ax`` or ``fig`` they are given, else into a new
:mod:`matplotlib.pyplot` figure, and return it; none calls ``plt.show``, so they are safe
under the Agg backend and in scripts that only save files.

Views (``view``):

* ``"3d"``: a 3-D scatter of ``(x, y, z)`` as given;
* ``"top"``: looking down the z axis, x to the right and y up;
* ``"bev"``: bird's-eye view of a camera frame (x right, y down, z forward, as in KITTI,
  FlyingThings3D and OpenCV): x to the right, z (distance ahead) up the page; of a z-up
  LiDAR frame (``frame="lidar"``, or detected as one): as ``"top"``;
* ``"camera"``: the points as a pinhole camera at the origin sees them; in pixels when
  ``camera`` gives the intrinsics (``fx``, ``fy``, ``cx``, ``cy``, ``width``, ``height``),
  else in normalised image coordinates ``(x / z, y / z)``.
"""

from mmreg.plotting._clusters import plot_clusters
from mmreg.plotting._comparison import plot_comparison
from mmreg.plotting._result import plot_result
from mmreg.plotting._street import plot_street
from mmreg.plotting._style import (
    BACKGROUND_COLOR,
    OUTLIER_COLOR,
    VIEWS,
    cluster_colors,
    cluster_palette,
)
from mmreg.plotting._sweep import plot_sweep

__all__ = [
    "BACKGROUND_COLOR",
    "OUTLIER_COLOR",
    "VIEWS",
    "cluster_colors",
    "cluster_palette",
    "plot_clusters",
    "plot_comparison",
    "plot_result",
    "plot_street",
    "plot_sweep",
]
