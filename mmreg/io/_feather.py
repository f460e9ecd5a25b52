"""Feather tables (Argoverse 2 sweeps, poses, annotations, flows), read strictly."""

import numpy as np

from mmreg.io._checks import _check_readable


def read_feather(path, columns, what, optional=(), nulls_as_nan=()):
    """``{column: ndarray}`` of a feather file; ValueError naming it when unreadable.

    ``columns`` must all be present; those of ``optional`` are read when present. Missing
    values are an error, except in the float columns of ``nulls_as_nan`` (a LiDAR's
    invalid returns, as pandas writes NaN), where they read as NaN.
    """
    import pyarrow as pa
    import pyarrow.feather as feather

    path = _check_readable(path, what)
    try:
        table = feather.read_table(path)
    except (pa.ArrowException, OSError, ValueError, EOFError) as exc:
        raise ValueError(
            f"{path}: cannot be read as a feather file ({what}; truncated or corrupt?): {exc}"
        ) from exc
    missing = [c for c in columns if c not in table.column_names]
    if missing:
        raise ValueError(
            f"{path}: missing column(s) {', '.join(missing)} ({what}); it has "
            f"{', '.join(table.column_names) or 'no columns'}."
        )
    out = {}
    for name in tuple(columns) + tuple(c for c in optional if c in table.column_names):
        column = table.column(name)
        if column.null_count and name in nulls_as_nan and pa.types.is_floating(column.type):
            column = column.cast(pa.float64()).fill_null(float("nan"))
        if column.null_count:
            raise ValueError(f"{path}: column {name} has {column.null_count} missing values.")
        try:
            out[name] = column.to_numpy()
        except (pa.ArrowException, ValueError) as exc:
            raise ValueError(f"{path}: column {name} cannot be read ({what}): {exc}") from exc
    return out


def numeric_column(values, path, name, kind="f", *, finite=True):
    """``values`` as int64 (``kind='i'``) or float64; ValueError naming the column otherwise."""
    values = np.asarray(values)
    if values.dtype.kind not in ("iu" if kind == "i" else "iuf"):
        raise ValueError(f"{path}: column {name} must be numeric; got dtype {values.dtype}.")
    if kind == "i":
        return values.astype(np.int64)
    values = values.astype(np.float64)
    if finite and not np.all(np.isfinite(values)):
        raise ValueError(f"{path}: column {name} holds NaN or infinite values.")
    return values
