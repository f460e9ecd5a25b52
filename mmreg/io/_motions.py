"""Fitted motions as JSON: one object per cluster."""

import json

import numpy as np

from mmreg.io._atomic import atomic_write
from mmreg.io._checks import _as_numeric, _check_readable
from mmreg.io._labels import _check_label_array


def _rotation_angle_deg(rotation):
    cos = (np.trace(rotation) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


def _optional(values, n, name, kind):
    """``values`` checked to length ``n`` (or None)."""
    if values is None:
        return None
    values = np.asarray(values)
    if values.shape != (n,):
        raise ValueError(f"{name} must have shape ({n},), one per motion; got {values.shape}.")
    if kind == "bool":
        if values.dtype.kind != "b":
            raise TypeError(f"{name} must be booleans; got dtype {values.dtype}.")
        return [bool(v) for v in values]
    if kind == "int":
        return [int(v) for v in _check_label_array(values, name)]
    values = _as_numeric(values, name, name)
    return [float(v) if np.isfinite(v) else None for v in values]  # unknown: JSON null


def write_motions(path, rotations, translations, *, sigmas=None, sizes=None, moving=None):
    """Write rigid motions to a JSON file, atomically.

    The file holds a list with one object per motion ``k``::

        {"label": k, "transform": 4x4, "rotation": 3x3, "translation": 3,
         "rotation_angle_deg": float, "sigma": float or null, "size": int or null,
         "moving": bool or null}

    where ``transform = [[R, t], [0, 0, 0, 1]]`` maps ``a`` to ``R a + t``. Floats are
    written with Python's shortest round-trip representation, so :func:`read_motions`
    returns exactly the arrays written.

    Parameters
    ----------
    path : str or path-like
        The JSON file (any extension; ``.json`` is customary).
    rotations : array-like of shape (K, 3, 3)
    translations : array-like of shape (K, 3)
    sigmas : array-like of shape (K,), optional
        Noise scale of every motion (e.g. a fitted estimator's ``sigmas_``); NaN or
        infinity (unknown) is written as ``null`` and read back as NaN.
    sizes : array-like of shape (K,), optional
        Number of points of every motion.
    moving : array-like of bool, shape (K,), optional
        Whether every motion counts as moving (e.g. differs from the background's).

    Raises
    ------
    ValueError
        If the shapes do not match or a rotation or translation is NaN or infinity.
    TypeError
        If ``sizes`` are not integers or ``moving`` not booleans.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> import numpy as np
    >>> from mmreg.io import read_motions, write_motions
    >>> rotations = np.stack([np.eye(3), [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]])
    >>> translations = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 0.5]])
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     write_motions(Path(folder) / "motions.json", rotations, translations,
    ...                   sizes=[120, 30], moving=[False, True])
    ...     motions = read_motions(Path(folder) / "motions.json")
    >>> motions["transforms"].shape, motions["rotation_angles_deg"].tolist()
    ((2, 4, 4), [0.0, 90.0])
    >>> motions["sizes"].tolist(), motions["moving"].tolist(), motions["sigmas"]
    ([120, 30], [False, True], None)
    """
    rotations = _as_numeric(rotations, "rotations", "rotations")
    translations = _as_numeric(translations, "translations", "translations")
    if rotations.ndim != 3 or rotations.shape[1:] != (3, 3):
        raise ValueError(f"rotations must have shape (K, 3, 3); got {rotations.shape}.")
    n_motions = len(rotations)
    if translations.shape != (n_motions, 3):
        raise ValueError(
            f"translations must have shape ({n_motions}, 3) to match rotations; got "
            f"{translations.shape}."
        )
    if not (np.all(np.isfinite(rotations)) and np.all(np.isfinite(translations))):
        raise ValueError("rotations and translations must be finite (no NaN or infinity).")
    sigmas = _optional(sigmas, n_motions, "sigmas", "float")
    sizes = _optional(sizes, n_motions, "sizes", "int")
    moving = _optional(moving, n_motions, "moving", "bool")
    records = []
    for k in range(n_motions):
        transform = np.eye(4)
        transform[:3, :3] = rotations[k]
        transform[:3, 3] = translations[k]
        records.append(
            {
                "label": k,
                "transform": transform.tolist(),
                "rotation": rotations[k].tolist(),
                "translation": translations[k].tolist(),
                "rotation_angle_deg": _rotation_angle_deg(rotations[k]),
                "sigma": None if sigmas is None else sigmas[k],
                "size": None if sizes is None else sizes[k],
                "moving": None if moving is None else moving[k],
            }
        )
    with atomic_write(path, "w") as handle:
        json.dump(records, handle, indent=2, allow_nan=False)
        handle.write("\n")


def _motion_field(records, key, path, convert, missing=None):
    """One optional field of every record: None when null in all, else an array.

    A null among values is ``missing`` when given, else a ValueError.
    """
    values = [record.get(key) for record in records]
    if all(v is None for v in values):
        return None
    if missing is not None:
        values = [missing if v is None else v for v in values]
    if any(v is None for v in values):
        k = next(i for i, v in enumerate(values) if v is None)
        raise ValueError(f"{path}: motion {k} has no {key!r} while others do.")
    try:
        return convert(values)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{path}: field {key!r} is malformed: {exc}") from exc


def read_motions(path):
    """Read rigid motions written by :func:`write_motions`.

    Each object of the list needs ``"rotation"`` and ``"translation"``, or
    ``"transform"`` (4x4); every other field is optional.

    Parameters
    ----------
    path : str or path-like
        A JSON file holding a list of motion objects.

    Returns
    -------
    motions : dict
        ``rotations`` (K, 3, 3), ``translations`` (K, 3), ``transforms`` (K, 4, 4),
        ``labels`` (K,) int, ``rotation_angles_deg`` (K,), and ``sigmas`` (K,) float
        (NaN where null), ``sizes`` (K,) int, ``moving`` (K,) bool, each ``None`` when
        the file has none.

    Raises
    ------
    FileNotFoundError
        If the file is missing.
    ValueError
        If it is not valid JSON, not a list of motion objects, or a matrix has the wrong
        shape or is not finite.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> from mmreg.io import read_motions
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     path = Path(folder) / "motions.json"
    ...     _ = path.write_text('[{"rotation": [[1,0,0],[0,1,0],[0,0,1]], "translation": [1,2,3]}]')
    ...     motions = read_motions(path)
    >>> motions["translations"].tolist(), motions["sizes"]
    ([[1.0, 2.0, 3.0]], None)
    """
    path = _check_readable(path)
    try:
        with open(path, encoding="utf-8") as handle:
            records = json.load(handle)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: is not valid JSON: {exc}") from exc
    except OSError as exc:
        raise ValueError(f"{path}: cannot be read: {exc}") from exc
    if not isinstance(records, list) or not all(isinstance(r, dict) for r in records):
        raise ValueError(f"{path}: must hold a JSON list of motion objects.")
    rotations, translations = [], []
    for k, record in enumerate(records):
        try:
            if "rotation" in record and "translation" in record:
                rotation = np.array(record["rotation"], dtype=float)
                translation = np.array(record["translation"], dtype=float)
            elif "transform" in record:
                transform = np.array(record["transform"], dtype=float)
                if transform.shape != (4, 4):
                    raise ValueError(f"transform has shape {transform.shape}, not (4, 4)")
                rotation, translation = transform[:3, :3], transform[:3, 3]
            else:
                raise ValueError("needs 'rotation' and 'translation', or 'transform'")
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{path}: motion {k} is malformed: {exc}.") from exc
        if rotation.shape != (3, 3) or translation.shape != (3,):
            raise ValueError(
                f"{path}: motion {k} has a rotation of shape {rotation.shape} and a "
                f"translation of shape {translation.shape}; expected (3, 3) and (3,)."
            )
        if not (np.all(np.isfinite(rotation)) and np.all(np.isfinite(translation))):
            raise ValueError(f"{path}: motion {k} contains NaN or infinity.")
        rotations.append(rotation)
        translations.append(translation)
    rotations = np.array(rotations, dtype=float).reshape(-1, 3, 3)
    translations = np.array(translations, dtype=float).reshape(-1, 3)
    transforms = np.tile(np.eye(4), (len(records), 1, 1))
    transforms[:, :3, :3] = rotations
    transforms[:, :3, 3] = translations
    labels = _motion_field(records, "label", path, lambda v: _check_label_array(v, path))
    return {
        "rotations": rotations,
        "translations": translations,
        "transforms": transforms,
        "labels": np.arange(len(records)) if labels is None else labels,
        "rotation_angles_deg": np.array([_rotation_angle_deg(r) for r in rotations]),
        "sigmas": _motion_field(
            records, "sigma", path, lambda v: np.array(v, dtype=float), missing=np.nan
        ),
        "sizes": _motion_field(records, "size", path, lambda v: _check_label_array(v, path)),
        "moving": _motion_field(records, "moving", path, lambda v: np.array(v, dtype=bool)),
    }
