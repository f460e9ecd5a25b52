"""Results of the checks of Definitions 1 and 2: truthy when every condition holds."""

from dataclasses import dataclass, field

__all__ = ["Condition", "GoodClusteringReport", "GroundTruthReport", "Report"]


@dataclass(frozen=True)
class Condition:
    """One condition of a definition, whether it holds, and why (or why not).

    Attributes
    ----------
    name : str
        Short name, e.g. ``"separation"``.
    holds : bool
    detail : str
        The measured quantity behind the verdict, or what breaks it.
    """

    name: str
    holds: bool
    detail: str

    def __bool__(self):
        return self.holds

    def __str__(self):
        return f"[{'ok' if self.holds else 'FAIL'}] {self.name}: {self.detail}"


@dataclass(frozen=True, eq=False)
class Report:
    """The conditions of a definition; truthy iff all of them hold.

    ``report["name"]`` is the :class:`Condition` of that name; ``report.failures`` the
    conditions that fail; ``str(report)`` one line per condition.
    """

    title: str
    conditions: tuple = field(repr=False)

    def __bool__(self):
        return all(c.holds for c in self.conditions)

    @property
    def holds(self):
        """Whether every condition holds."""
        return bool(self)

    @property
    def failures(self):
        """The conditions that do not hold, in the order of the definition."""
        return tuple(c for c in self.conditions if not c.holds)

    def __getitem__(self, name):
        for condition in self.conditions:
            if condition.name == name:
                return condition
        raise KeyError(f"no condition {name!r}; conditions: {[c.name for c in self.conditions]}")

    def __str__(self):
        verdict = "holds" if self else "fails (" + ", ".join(c.name for c in self.failures) + ")"
        return "\n".join([f"{self.title} {verdict}:"] + [f"  {c}" for c in self.conditions])


@dataclass(frozen=True, eq=False)
class GroundTruthReport(Report):
    """Definition 1 (ground truth) checked on a labelled scene.

    Attributes
    ----------
    conditions : tuple of Condition
        ``partition``, ``rigid``, ``noise``, ``connected``, ``separation``, ``bounded``,
        ``outliers``, in the order of the definition.
    n_objects : int
        ``M``.
    noise : ndarray of shape (n_objects,)
        Largest ``|b - R_j a - t_j|_inf`` over each object (0 for an empty object).
    pieces : ndarray of shape (n_objects,)
        Number of ``tau``-connected pieces of each object (1 when connected).
    separation : float
        Smallest distance between a-points of two different objects (``inf`` if M < 2).
    outlier_gap : float
        Smallest distance from an outlier's a-point to an object's (``inf`` if none).
    bound : float
        ``B = max_i ||a_i||``, the radius of the bounded point cloud.
    """

    n_objects: int = 0
    noise: object = None
    pieces: object = None
    separation: float = float("inf")
    outlier_gap: float = float("inf")
    bound: float = 0.0


@dataclass(frozen=True, eq=False)
class GoodClusteringReport(Report):
    """Definition 2 ((tau, alpha, m0)-good clustering) checked against a ground truth.

    Attributes
    ----------
    conditions : tuple of Condition
        ``partition``, ``count`` (``K >= M``), ``connected``, ``size``, ``pure``,
        ``identifying``.
    n_clusters : int
        ``K``, the number of initial clusters.
    n_objects : int
        ``M``.
    sizes : ndarray of shape (n_clusters,)
        ``|H_k|`` for the clusters numbered ``0..K-1`` in increasing label order.
    pieces : ndarray of shape (n_clusters,)
        Number of ``tau``-connected pieces of each cluster.
    ratios : ndarray of shape (n_objects,)
        For each object ``G``, ``|H*| / max_{H in H_G, H != H*} |H|`` (``inf`` when a
        single cluster meets ``G``; ``nan`` for an empty object).
    max_alpha : float
        ``min(ratios)``: the identifying condition holds for every ``alpha`` below it and
        for no ``alpha`` at or above it.
    max_m0 : int
        Smallest size of a cluster that condition 2 applies to: the largest ``m0`` that
        holds.
    """

    n_clusters: int = 0
    n_objects: int = 0
    sizes: object = None
    pieces: object = None
    ratios: object = None
    max_alpha: float = float("inf")
    max_m0: int = 0
