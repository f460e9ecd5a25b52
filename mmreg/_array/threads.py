"""BLAS on one thread, where a second one only waits."""

import functools

from threadpoolctl import ThreadpoolController

__all__ = ["single_threaded_blas"]


@functools.cache
def _blas_controller():
    return ThreadpoolController()


def single_threaded_blas():
    """Context in which BLAS runs on one thread.

    The products of a registration are small (a block of rows times a few dozen motions,
    a 3 x 3 system per body): a second BLAS thread only adds synchronisation, which costs
    far more than the product as soon as the cores are busy.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg._array.threads import single_threaded_blas
    >>> with single_threaded_blas():
    ...     product = np.ones((3, 3)) @ np.ones((3, 3))
    >>> product.tolist()[0]
    [3.0, 3.0, 3.0]
    """
    return _blas_controller().limit(limits=1, user_api="blas")
