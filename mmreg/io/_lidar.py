"""LiDAR sweeps as their users have them: KITTI, nuScenes, Argoverse 2 files and ROS bags.

:func:`mmreg.io.read_point_cloud` dispatches here for the single-sweep formats;
:mod:`mmreg.datasets._sequences` reads the bags frame by frame.

=================  ==========================================================================
``*.bin``          KITTI velodyne: float32 little-endian ``x y z reflectance``, 16 bytes a point
``*.pcd.bin``      nuScenes LiDAR: float32 little-endian ``x y z intensity ring``, 20 bytes
``*.feather``      Argoverse 2 sweep: columns ``x y z`` (any float), optional ``intensity``,
                   ``laser_number``, ``offset_ns`` (capture time after the sweep's timestamp)
ROS bags           ``*.bag`` (ROS 1), a ROS 2 bag folder (``metadata.yaml``) or its ``*.db3`` /
                   ``*.mcap`` file, with a ``sensor_msgs/PointCloud2`` topic (through the
                   optional ``rosbags`` package: ``pip install "mmreg[ros]"``)
=================  ==========================================================================

Invalid returns are kept as the sensor wrote them: NaN rows (a PointCloud2 with
``is_dense`` false, an organised cloud) and all-zero rows stay in place, so the rows keep
their order and their per-point times. The estimators count and drop them; a reader that
dropped them would make an (n, 3) flow or label file written for the sweep misaligned.
"""

import contextlib
import re
from pathlib import Path

import numpy as np

from mmreg.io._feather import numeric_column, read_feather

# Bytes of one point, and how many float32 it holds, of the flat binary formats.
_FLAT_FORMATS = {
    "kitti": (4, "KITTI velodyne .bin", "float32 x y z reflectance"),
    "nuscenes": (5, "nuScenes .pcd.bin", "float32 x y z intensity ring"),
}
# Coordinates this large are no LiDAR return in any units (1,000 km in millimetres).
_WILD = 1e9
# Rows of a flat file that may be strays before its values are refused as another layout.
_STRAY_SHARE = 0.1
ROS_INSTALL = 'pip install "mmreg[ros]"'
BAG_SUFFIXES = (".bag", ".db3", ".mcap")
POINTCLOUD2 = "sensor_msgs/msg/PointCloud2"
# PointField datatypes (sensor_msgs/PointField): code -> numpy type.
_POINTFIELD_TYPES = {
    1: "i1",
    2: "u1",
    3: "i2",
    4: "u2",
    5: "i4",
    6: "u4",
    7: "f4",
    8: "f8",
}
# Per-point capture time fields of common drivers: Ouster "t" (uint32 ns after the
# scan's stamp), velodyne_pointcloud "time" (float32 s after it), Hesai / Robosense
# "timestamp" (float64 absolute s), Livox "offset_time" (uint32 ns after it).
_TIME_FIELDS = ("t", "time", "timestamp", "offset_time")
# A float time larger than this (seconds) is absolute (since 1970), not after the stamp.
_ABSOLUTE_SECONDS = 1e6
_AV2_SWEEP_NAME = re.compile(r"^\d+\.feather$")


def lidar_kind(path):
    """``"kitti"``, ``"nuscenes"``, ``"feather"``, ``"bag"`` or None, from the path's name.

    A folder holding ``metadata.yaml`` is a ROS 2 bag.
    """
    path = Path(path)
    name = path.name.lower()
    if name.endswith(".pcd.bin"):
        return "nuscenes"
    if name.endswith(".bin"):
        return "kitti"
    if name.endswith(".feather"):
        return "feather"
    if name.endswith(BAG_SUFFIXES) or (path.is_dir() and (path / "metadata.yaml").is_file()):
        return "bag"
    return None


def read_lidar_file(path, kind=None):
    """``(points, times, intensity)`` of one sweep file (not a bag).

    ``points`` (n, 3) float64, invalid rows kept; ``times`` (n,) seconds after the
    sweep's timestamp or None; ``intensity`` (n,) float64 or None. ``path`` has been
    checked readable.
    """
    kind = kind or lidar_kind(path)
    if kind in _FLAT_FORMATS:
        return _read_flat(path, kind)
    if kind == "feather":
        return _read_feather_sweep(path)
    if kind == "bag":
        raise ValueError(
            f"{path}: is a bag of many frames, not one point cloud; read its frames with "
            "mmreg.datasets.open_sequence (on the command line: --topic and --frame)."
        )
    raise ValueError(f"{path}: not a LiDAR sweep file (.bin, .pcd.bin, .feather).")


def _read_flat(path, kind):
    width, name, layout = _FLAT_FORMATS[kind]
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise ValueError(f"{path}: cannot be read: {exc}") from exc
    step = 4 * width
    if len(data) % step:
        raise ValueError(
            f"{path}: {len(data):,} bytes is not a whole number of {name} points ({step} "
            f"bytes each: {layout}); truncated, or not a {name} file."
        )
    if not data:
        raise ValueError(f"{path}: holds no points (0 bytes).")
    values = np.frombuffer(data, dtype="<f4").reshape(-1, width)
    _check_flat_values(values, path, name, layout)
    return values[:, :3].astype(np.float64), None, values[:, 3].astype(np.float64)


def _check_flat_values(values, path, name, layout):
    """One clear error where the floats are not ``layout``, though their bytes fit it:
    float64 values read as float32 pairs (coordinates of 1e9 and more, in any units), or
    points of three floats read as four (their coordinates in the reflectance, which is
    never negative). A share of stray rows (NaN padding, a bad return) passes."""
    coordinates = values[:, :3]
    wild = np.isinf(coordinates).any(axis=1) | (np.abs(coordinates) >= _WILD).any(axis=1)
    if wild.mean() > _STRAY_SHARE:
        example = coordinates[np.flatnonzero(wild)[0]]
        raise ValueError(
            f"{path}: {wild.mean():.0%} of its points lie {_WILD:g} or more from the sensor "
            f"(e.g. {np.array2string(example, precision=3)}): not {layout} (float64 "
            f"values?), or not a {name} file."
        )
    negative = values[:, 3] < 0
    if negative.mean() > _STRAY_SHARE:
        raise ValueError(
            f"{path}: the 4th float of {negative.mean():.0%} of its points (the "
            f"reflectance) is negative: not {layout} (x y z alone, 12 bytes a point? "
            f"np.fromfile(path, '<f4').reshape(-1, 3) reads those), or not a {name} file."
        )


def _read_feather_sweep(path):
    columns = read_feather(
        path,
        ("x", "y", "z"),
        "LiDAR sweep: x y z",
        optional=("intensity", "offset_ns"),
        nulls_as_nan=("x", "y", "z", "intensity"),
    )
    points = np.column_stack([numeric_column(columns[c], path, c, finite=False) for c in "xyz"])
    if len(points) == 0:
        raise ValueError(f"{path}: holds no points (0 rows).")
    times = None
    if "offset_ns" in columns:
        times = numeric_column(columns["offset_ns"], path, "offset_ns", "i") * 1e-9
    intensity = None
    if "intensity" in columns:
        intensity = numeric_column(columns["intensity"], path, "intensity", finite=False)
    return points.reshape(-1, 3), times, intensity


def av2_timestamp_ns(path):
    """Nanoseconds of an Argoverse 2 sweep named ``<timestamp_ns>.feather``, else None."""
    name = Path(path).name
    return int(name.split(".")[0]) if _AV2_SWEEP_NAME.match(name) else None


# --------------------------------------------------------------------------- ROS bags
def _any_reader():
    try:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore
    except ImportError as exc:
        raise ImportError(
            f"reading ROS bags needs the rosbags package: {ROS_INSTALL} (or pip install rosbags)."
        ) from exc
    return AnyReader, get_typestore(Stores.LATEST)


class Bag:
    """The PointCloud2 messages of one topic of a ROS 1 or ROS 2 bag, read one at a time.

    The bag is opened for each read (an open reader holds a file or a database
    connection, which neither pickles nor survives a fork). Opening it reads the topic's
    messages once, to index their receive times; ``read(k)`` then seeks to message ``k``
    by its time.

    Parameters
    ----------
    path : path-like
        A ``.bag`` file (ROS 1), a ROS 2 bag folder (``metadata.yaml``) or its ``.db3`` /
        ``.mcap`` file.
    topic : str, optional
        Needed only when the bag holds several PointCloud2 topics.

    Attributes
    ----------
    path : pathlib.Path
    topic : str
    log_times : ndarray of int64
        The bag's receive time of every message (nanoseconds), in the bag's order.
    """

    def __init__(self, path, topic=None):
        self.path = Path(path)
        if not self.path.exists():
            raise FileNotFoundError(f"{self.path}: no such file or folder (a ROS bag).")
        with self._open() as reader:
            clouds = sorted({c.topic for c in reader.connections if c.msgtype == POINTCLOUD2})
            if topic is None:
                if not clouds:
                    raise ValueError(f"{self.path}: holds no {POINTCLOUD2} topic.")
                if len(clouds) > 1:
                    raise ValueError(
                        f"{self.path}: holds {len(clouds)} PointCloud2 topics ("
                        f"{', '.join(clouds)}); choose one with --topic (topic=)."
                    )
                topic = clouds[0]
            elif topic not in clouds:
                raise ValueError(
                    f"{self.path}: no PointCloud2 topic {topic!r}; its PointCloud2 topics: "
                    f"{', '.join(clouds) or 'none'}."
                )
            self.topic = topic
            connections = [c for c in reader.connections if c.topic == topic]
            self.log_times = np.array(
                [stamp for _, stamp, _ in reader.messages(connections=connections)],
                dtype=np.int64,
            )
        if len(self.log_times) == 0:
            raise ValueError(f"{self.path}: topic {topic!r} holds no messages.")

    @contextlib.contextmanager
    def _open(self):
        """An open AnyReader, closed after the block; ValueError when it cannot be read."""
        AnyReader, typestore = _any_reader()
        try:
            reader = AnyReader([self.path], default_typestore=typestore)
            reader.open()
        except Exception as exc:  # rosbags raises its own errors, not ValueError
            raise ValueError(
                f"{self.path}: cannot be read as a ROS bag: {' '.join(str(exc).split())}"
            ) from exc
        try:
            yield reader
        finally:
            reader.close()

    def __len__(self):
        return len(self.log_times)

    def read(self, k):
        """``(points, stamp, times)`` of message ``k``: see :func:`decode_pointcloud2`."""
        stamp = int(self.log_times[k])
        # Messages sharing this receive time before k: skip them.
        skip = int(np.count_nonzero(self.log_times[:k] == stamp))
        with self._open() as reader:
            connections = [c for c in reader.connections if c.topic == self.topic]
            messages = reader.messages(connections=connections, start=stamp, stop=stamp + 1)
            for n, (connection, _, raw) in enumerate(messages):
                if n == skip:
                    msg = reader.deserialize(raw, connection.msgtype)
                    break
            else:  # pragma: no cover - the index was read from the same bag
                raise ValueError(f"{self.path}: message {k} of {self.topic} vanished.")
        source = f"{self.path} [{self.topic} message {k}]"
        points, stamp_s, times = decode_pointcloud2(msg, source)
        return points, (stamp * 1e-9 if stamp_s is None else stamp_s), times


def decode_pointcloud2(msg, source="PointCloud2"):
    """``(points, stamp, times)`` of a ``sensor_msgs/PointCloud2`` message.

    Fields ``x``, ``y``, ``z`` of any float type (float32 or float64) at their offsets,
    ``point_step`` bytes a point, ``row_step`` bytes a row (padding at a row's end
    skipped), big or little endian. Rows holding NaN (``is_dense`` false) are kept.

    Returns
    -------
    points : ndarray of shape (width * height, 3), float64
    stamp : float or None
        The header's stamp in seconds, None when it is zero.
    times : ndarray of shape (n,) or None
        Per-point capture times in seconds after ``stamp`` from a field ``t``, ``time``,
        ``timestamp`` or ``offset_time``: integers are nanoseconds, floats seconds; float
        times beyond 1e6 s are absolute and have the stamp subtracted.
    """
    fields = {f.name: f for f in msg.fields}
    missing = [name for name in "xyz" if name not in fields]
    if missing:
        raise ValueError(
            f"{source}: a PointCloud2 without field(s) {', '.join(missing)}; it has "
            f"{', '.join(fields) or 'no fields'}."
        )
    order = ">" if msg.is_bigendian else "<"
    names, formats, offsets = [], [], []
    for name in ("x", "y", "z", *_TIME_FIELDS):
        field = fields.get(name)
        if field is None:
            continue
        code = _POINTFIELD_TYPES.get(int(field.datatype))
        if code is None:
            raise ValueError(f"{source}: field {name} has unknown datatype {field.datatype}.")
        if name in ("x", "y", "z") and code[0] != "f":
            raise ValueError(
                f"{source}: field {name} is {np.dtype(code).name}; x, y, z must be float32 "
                "or float64."
            )
        if name not in ("x", "y", "z") and names[3:]:
            continue  # one time field is enough
        names.append(name)
        formats.append(order + code)
        offsets.append(int(field.offset))
    width, height = int(msg.width), int(msg.height)
    point_step, row_step = int(msg.point_step), int(msg.row_step)
    ends = [o + np.dtype(f).itemsize for o, f in zip(offsets, formats, strict=True)]
    if max(ends) > point_step:
        raise ValueError(
            f"{source}: its fields end at byte {max(ends)} but point_step is {point_step}."
        )
    if row_step < width * point_step:
        raise ValueError(
            f"{source}: row_step {row_step} is less than width {width} x point_step {point_step}."
        )
    data = np.frombuffer(bytes(msg.data), dtype=np.uint8)
    if len(data) != row_step * height:
        raise ValueError(
            f"{source}: holds {len(data):,} bytes of data; height {height} x row_step "
            f"{row_step} = {row_step * height:,} were announced."
        )
    if width * height == 0:
        raise ValueError(f"{source}: holds no points (width {width}, height {height}).")
    rows = data.reshape(height, row_step)[:, : width * point_step]
    dtype = np.dtype(
        {"names": names, "formats": formats, "offsets": offsets, "itemsize": point_step}
    )
    cloud = np.ascontiguousarray(rows).view(dtype).reshape(-1)
    points = np.column_stack([cloud[c].astype(np.float64) for c in "xyz"])
    sec, nanosec = _stamp(msg.header.stamp)
    stamp = None if sec == 0 and nanosec == 0 else sec + nanosec * 1e-9
    times = None
    if len(names) > 3:
        raw = cloud[names[3]]
        times = raw.astype(np.float64) * (1e-9 if raw.dtype.kind in "iu" else 1.0)
        if (
            raw.dtype.kind == "f"
            and stamp is not None
            and np.nanmax(np.abs(times)) > _ABSOLUTE_SECONDS
        ):
            # Absolute seconds: subtract in float64 from the stamp's parts, to keep precision.
            times = (raw.astype(np.float64) - sec) - nanosec * 1e-9
    return points, stamp, times


def _stamp(stamp):
    """``(sec, nanosec)`` of a ROS 2 ``builtin_interfaces/Time`` or ROS 1 ``time``."""
    sec = getattr(stamp, "sec", None)
    if sec is None:
        sec = getattr(stamp, "secs", 0)
    nanosec = getattr(stamp, "nanosec", None)
    if nanosec is None:
        nanosec = getattr(stamp, "nsecs", 0)
    return int(sec), int(nanosec)
