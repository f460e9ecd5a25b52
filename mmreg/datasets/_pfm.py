"""PFM and Middlebury ``.flo`` images: the float formats of FlyingThings3D.

PFM (portable float map) is a text header and raw 32-bit floats:

- line 1: ``PF`` (3 channels) or ``Pf`` (1 channel);
- line 2: ``width height``;
- line 3: the scale, whose sign gives the byte order (negative: little endian,
  positive: big endian) and whose magnitude is usually 1 and carries no meaning here;
- then ``height * width * channels`` floats, channels interleaved, rows from the **bottom**
  of the image to the top.

``.flo`` (Middlebury optical flow) is the float ``202021.25`` (the bytes ``PIEH``), the width
and height as little-endian int32, then ``height * width`` pairs ``(u, v)`` of little-endian
float32, rows from top to bottom.
"""

import numpy as np

from mmreg.io import atomic_write
from mmreg.io._checks import _check_readable

__all__ = ["read_flo", "read_pfm", "write_flo", "write_pfm"]

_FLO_MAGIC = 202021.25


def _header_tokens(data, count):
    """The first ``count`` whitespace-separated tokens and the offset after the next byte."""
    tokens, pos = [], 0
    while len(tokens) < count:
        while pos < len(data) and data[pos : pos + 1].isspace():
            pos += 1
        start = pos
        while pos < len(data) and not data[pos : pos + 1].isspace():
            pos += 1
        if start == pos:
            break
        tokens.append(data[start:pos])
        if pos - start > 32:  # binary garbage, not a header token
            break
    return tokens, pos + 1  # a single whitespace byte ends the header


def read_pfm(path):
    """Read a PFM image into an array with row 0 at the top.

    Parameters
    ----------
    path : str or path-like
        A ``.pfm`` file, either byte order.

    Returns
    -------
    image : ndarray of shape (H, W) or (H, W, 3), dtype float32
        ``(H, W)`` for a ``Pf`` (grey) file, ``(H, W, 3)`` for a ``PF`` (colour) file.

    Raises
    ------
    FileNotFoundError
        If the file is missing.
    ValueError
        If the header is malformed or the data are truncated or too long.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> import numpy as np
    >>> from mmreg.datasets import read_pfm, write_pfm
    >>> image = np.arange(6, dtype=np.float32).reshape(2, 3)
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     write_pfm(Path(folder) / "disparity.pfm", image)
    ...     print(read_pfm(Path(folder) / "disparity.pfm").tolist())
    [[0.0, 1.0, 2.0], [3.0, 4.0, 5.0]]
    """
    path = _check_readable(path)
    data = path.read_bytes()
    tokens, offset = _header_tokens(data[:256], 4)
    if len(tokens) < 4 or tokens[0] not in (b"PF", b"Pf"):
        raise ValueError(f"{path}: is not a PFM file (no 'PF'/'Pf' header).")
    channels = 3 if tokens[0] == b"PF" else 1
    try:
        width, height, scale = int(tokens[1]), int(tokens[2]), float(tokens[3])
    except ValueError:
        raise ValueError(
            f"{path}: malformed PFM header (width, height and scale must be numbers)."
        ) from None
    if width < 1 or height < 1 or scale == 0 or not np.isfinite(scale):
        raise ValueError(
            f"{path}: malformed PFM header (width={width}, height={height}, scale={scale})."
        )
    expected = width * height * channels * 4
    found = len(data) - offset
    if found != expected:
        raise ValueError(
            f"{path}: corrupt PFM file: the header announces {width} x {height} x {channels} "
            f"floats ({expected} bytes) but {found} bytes follow it."
        )
    dtype = np.dtype("<f4" if scale < 0 else ">f4")
    image = np.frombuffer(data, dtype=dtype, offset=offset)
    shape = (height, width, 3) if channels == 3 else (height, width)
    return np.ascontiguousarray(np.flipud(image.reshape(shape)), dtype=np.float32)


def write_pfm(path, image, *, little_endian=True):
    """Write an image as a PFM file, atomically (rows stored bottom to top).

    Parameters
    ----------
    path : str or path-like
        The file to write.
    image : array-like of shape (H, W) or (H, W, 3)
        Row 0 at the top; stored as float32.
    little_endian : bool, default=True
        Byte order (the scale written is -1.0 for little endian, 1.0 for big endian).

    Raises
    ------
    ValueError
        If ``image`` has another shape.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> import numpy as np
    >>> from mmreg.datasets import read_pfm, write_pfm
    >>> flow = np.zeros((2, 2, 3), dtype=np.float32)
    >>> flow[..., 0] = 1.5
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     write_pfm(Path(folder) / "flow.pfm", flow, little_endian=False)
    ...     print(read_pfm(Path(folder) / "flow.pfm")[0, 1].tolist())
    [1.5, 0.0, 0.0]
    """
    image = np.asarray(image, dtype=np.float32)
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[..., 0]
    if not (image.ndim == 2 or (image.ndim == 3 and image.shape[2] == 3)) or 0 in image.shape:
        raise ValueError(
            f"image must have shape (H, W) or (H, W, 3) to be written as PFM; got {image.shape}."
        )
    height, width = image.shape[:2]
    magic = "PF" if image.ndim == 3 else "Pf"
    dtype = "<f4" if little_endian else ">f4"
    scale = -1.0 if little_endian else 1.0
    header = f"{magic}\n{width} {height}\n{scale}\n".encode("ascii")
    with atomic_write(path) as handle:
        handle.write(header)
        handle.write(np.flipud(image).astype(dtype).tobytes())


def read_flo(path):
    """Read a Middlebury ``.flo`` optical flow file.

    Parameters
    ----------
    path : str or path-like

    Returns
    -------
    flow : ndarray of shape (H, W, 2), dtype float32
        ``(u, v)`` per pixel: column and row displacement.

    Raises
    ------
    FileNotFoundError
        If the file is missing.
    ValueError
        If the magic number is wrong or the data are truncated or too long.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> import numpy as np
    >>> from mmreg.datasets._pfm import read_flo, write_flo
    >>> flow = np.stack([np.full((2, 3), 4.0), np.full((2, 3), -1.0)], axis=-1)
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     write_flo(Path(folder) / "flow.flo", flow)
    ...     print(read_flo(Path(folder) / "flow.flo")[1, 2].tolist())
    [4.0, -1.0]
    """
    path = _check_readable(path)
    data = path.read_bytes()
    if len(data) < 12 or np.frombuffer(data[:4], "<f4")[0] != _FLO_MAGIC:
        raise ValueError(f"{path}: is not a .flo file (wrong magic number).")
    width, height = (int(v) for v in np.frombuffer(data[4:12], "<i4"))
    if width < 1 or height < 1:
        raise ValueError(f"{path}: malformed .flo header (width={width}, height={height}).")
    expected = width * height * 2 * 4
    if len(data) - 12 != expected:
        raise ValueError(
            f"{path}: corrupt .flo file: the header announces {width} x {height} flow vectors "
            f"({expected} bytes) but {len(data) - 12} bytes follow it."
        )
    flow = np.frombuffer(data, dtype="<f4", offset=12).reshape(height, width, 2)
    return flow.astype(np.float32)


def write_flo(path, flow):
    """Write ``(H, W, 2)`` optical flow as a Middlebury ``.flo`` file, atomically."""
    flow = np.asarray(flow, dtype=np.float32)
    if flow.ndim != 3 or flow.shape[2] != 2 or 0 in flow.shape:
        raise ValueError(f"flow must have shape (H, W, 2); got {flow.shape}.")
    height, width = flow.shape[:2]
    with atomic_write(path) as handle:
        handle.write(np.array([_FLO_MAGIC], "<f4").tobytes())
        handle.write(np.array([width, height], "<i4").tobytes())
        handle.write(flow.astype("<f4").tobytes())
