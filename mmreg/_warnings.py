"""Warnings that point at the user's line, however deep inside mmreg they are raised.

A fixed ``stacklevel`` counts frames, and the count changes with the path: scikit-learn's
``_fit_context`` wraps every ``fit`` in a frame of ``sklearn/base.py``, a
:class:`~mmreg.SweepRegistration` fits a :class:`~mmreg.MultiModelRegistration` inside its
own ``fit``, and ``init=`` runs an initialiser inside the estimator's. :func:`warn` walks up
the stack instead, to the first frame outside mmreg and scikit-learn (``warnings.warn``'s
``skip_file_prefixes`` does this from Python 3.12 on).
"""

import os
import sys
import warnings

import sklearn

# Folders whose frames are not the user's: mmreg's own and scikit-learn's.
_INTERNAL = tuple(
    os.path.dirname(os.path.abspath(path)) + os.sep for path in (__file__, sklearn.__file__)
)


def user_stacklevel():
    """The ``stacklevel`` at which ``warnings.warn``, called by our caller, names the
    first frame outside mmreg and scikit-learn (or the outermost frame, if every one is
    internal)."""
    frame = sys._getframe(1)  # the function that calls warnings.warn: stacklevel 1
    level = 1
    while frame.f_back is not None and os.path.abspath(frame.f_code.co_filename).startswith(
        _INTERNAL
    ):
        frame = frame.f_back
        level += 1
    return level


def warn(message, category=UserWarning):
    """``warnings.warn(message, category)`` attributed to the user's line."""
    # Both count from this function's frame.
    warnings.warn(message, category, stacklevel=user_stacklevel())
