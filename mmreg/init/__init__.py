"""Initial clusterings for the EM: the partition Theorem 1 starts from."""

from mmreg.init._base import BaseInitializer
from mmreg.init._resolve import initial_labels

__all__ = ["BaseInitializer", "initial_labels"]
