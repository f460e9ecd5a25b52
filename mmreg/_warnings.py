"""Warnings that point at the user's line, however deep in mmreg (or scikit-learn) they arise."""

import os
import sys
import warnings

import sklearn

__all__ = ["warn_at_caller"]

# Frames in these folders are not the user's: mmreg's own and scikit-learn's wrappers
# (``_fit_context``, ``fit_predict``) between the user's call and the warning.
_LIBRARY_DIRS = (
    os.path.dirname(os.path.abspath(__file__)) + os.sep,
    os.path.dirname(os.path.abspath(sklearn.__file__)) + os.sep,
)


def warn_at_caller(message, category):
    """``warnings.warn`` with the ``stacklevel`` of the first frame outside mmreg and sklearn.

    A fixed ``stacklevel`` points at the wrong line as soon as the warning is raised
    from another depth (``fit`` through ``fit_predict``, or through scikit-learn's
    ``_fit_context`` wrapper).

    Parameters
    ----------
    message : str
    category : type of Warning

    Examples
    --------
    >>> import warnings
    >>> from mmreg._warnings import warn_at_caller
    >>> with warnings.catch_warnings(record=True) as caught:
    ...     warnings.simplefilter("always")
    ...     warn_at_caller("look here", UserWarning)
    >>> caught[0].filename.startswith("<doctest")  # this line, not mmreg's
    True
    """
    frame, level = sys._getframe(0), 1
    while frame.f_back is not None and os.path.abspath(frame.f_code.co_filename).startswith(
        _LIBRARY_DIRS
    ):
        frame, level = frame.f_back, level + 1
    warnings.warn(message, category, stacklevel=level)
