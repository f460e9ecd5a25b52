"""``mmreg register``'s LiDAR inputs: point files, sequences (bags, folders) and their times.

What a path holds decides how it is read: a point cloud, a LiDAR sweep file or an (n, 3)
array holds only points (the first sweep, with --target, --flow or --sweep); an (n, 6)
array holds correspondences; a ROS bag or a folder is a sequence whose frames K and K+1
(--frame K) are the two sweeps. Capture times come with the points where the files hold
them (Argoverse 2's ``offset_ns``, a PointCloud2's time field), the interval between the
sweeps from their timestamps (an AV2 file name, a bag message's stamp) unless --interval
gives it.
"""

import contextlib
import re
from pathlib import Path

from mmreg._cli._common import CLIError, one_line, reading

CLOUD_EXTENSIONS = (".ply", ".pcd", ".xyz")
ARRAY_EXTENSIONS = (".npy", ".csv", ".txt")
# Capture times beyond this many --interval from zero are not seconds after the sweep's
# reference time (nanoseconds, or absolute timestamps): a sweep lasts about one interval.
MAX_TIMES_PER_INTERVAL = 10.0


# The library's messages name a parameter and its option together: "pattern='*.bin'
# (--pattern '*.bin')", "--topic (topic=)", "topic= (--topic)". The command line names
# the option alone.
_BOTH = re.compile(r"\b\w+=(?:'[^']*'|\S*?) \((?:on the command line: )?(--[\w-]+[^)]*)\)")
_OPTION_THEN_NAME = re.compile(r"(--[\w-]+) \(\w+=\)")


def cli_words(message):
    """``message`` with the library's parameter spellings left out where it names the
    command-line option too.

    Examples
    --------
    >>> from mmreg._cli._lidar_input import cli_words
    >>> cli_words("choose one with pattern='*.bin' (--pattern '*.bin').")
    "choose one with --pattern '*.bin'."
    >>> cli_words("choose one with --topic (topic=); topic= (--topic) applies to a bag")
    'choose one with --topic; --topic applies to a bag'
    """
    return _OPTION_THEN_NAME.sub(r"\1", _BOTH.sub(r"\1", str(message)))


@contextlib.contextmanager
def option_words():
    """Errors raised inside speak of command-line options (:func:`cli_words`)."""
    try:
        yield
    except CLIError as error:
        raise CLIError(cli_words(one_line(error))) from None
    except (ValueError, FileNotFoundError) as error:
        raise type(error)(cli_words(one_line(error))) from error


def is_sequence(path):
    """Whether ``path`` is a ROS bag or a folder (a sequence of frames)."""
    from mmreg.io import _lidar as _lidar_files

    path = Path(path)
    return path.is_dir() or _lidar_files.lidar_kind(path) == "bag"


def _columns(path):
    """Columns of a 2-D ``.npy`` / ``.csv`` / ``.txt`` array (its header only, for .npy)."""
    import numpy as np

    from mmreg.io._arrays import _load_npy
    from mmreg.io._correspondences import _array_columns

    if path.suffix.lower() == ".npy":
        npy = np.lib.format
        with open(path, "rb") as handle:
            version = npy.read_magic(handle)
            if version == (1, 0):
                shape = npy.read_array_header_1_0(handle)[0]
            elif version == (2, 0):
                shape = npy.read_array_header_2_0(handle)[0]
            else:
                shape = _load_npy(path).shape
        return shape[1] if len(shape) == 2 else None
    return _array_columns(path, path.suffix.lower())


def holds_points_only(path):
    """Whether ``path`` holds points (a cloud, a LiDAR sweep, an (n, 3) array), not pairs.

    An array that cannot be read is not (its reader then says why).
    """
    from mmreg.io import _lidar as _lidar_files

    path = Path(path)
    if path.suffix.lower() in CLOUD_EXTENSIONS:
        return True
    if _lidar_files.lidar_kind(path) in ("kitti", "nuscenes", "feather"):
        return True
    if path.suffix.lower() in ARRAY_EXTENSIONS and path.is_file():
        try:
            return _columns(path) == 3
        except (ValueError, TypeError, OSError, SyntaxError):
            return False
    return False


def check_points_for(path, option):
    """A CLIError saying why ``path`` (not a-points alone) cannot go with ``option``."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".npz":
        raise CLIError(f"{path}: {option} applies to a-points alone; an .npz holds a and b")
    if suffix not in ARRAY_EXTENSIONS:
        return  # an unknown extension: the reader names it
    with reading(path):
        columns = _columns(path)
    if columns == 6:
        raise CLIError(
            f"{path}: {option} applies to a-points alone, an (n, 3) array; this one holds "
            "both a and b (6 columns)"
        )
    raise CLIError(
        f"{path}: {option} needs the a-points as an (n, 3) array; this one has "
        f"{'no 2-D shape' if columns is None else f'{columns} columns'}"
    )


def check_sequence_options(args):
    """--topic, --frame and --pattern apply to a sequence INPUT only; a CLIError otherwise."""
    sequence = is_sequence(args.input)
    options = (("--topic", args.topic), ("--frame", args.frame))
    options += (("--pattern", getattr(args, "pattern", None)),)
    given = [flag for flag, value in options if value is not None]
    if not sequence:
        if given:
            verb = "applies" if len(given) == 1 else "apply"
            raise CLIError(
                f"{args.input}: {' and '.join(given)} {verb} only to a ROS bag or a sequence "
                "folder as INPUT"
            )
        return
    if getattr(args, "pattern", None) is not None and not Path(args.input).is_dir():
        raise CLIError(f"{args.input}: --pattern chooses the frame files of a folder INPUT")
    if getattr(args, "sweep", None) is not None:
        raise CLIError(
            f"{args.input}: a sequence INPUT registers frame K (--frame) against frame K+1; "
            "drop --sweep"
        )
    if args.paper:
        raise CLIError(
            f"{args.input}: a sequence INPUT registers two raw sweeps (SweepRegistration); "
            "drop --paper"
        )


def read_frames(args):
    """Frames K and K+1 of a sequence INPUT (``--frame K``, default 0)."""
    from mmreg.datasets import open_sequence

    k = 0 if args.frame is None else args.frame
    with reading(args.input), option_words():
        try:
            pattern = getattr(args, "pattern", None)
            sequence = open_sequence(args.input, topic=args.topic, pattern=pattern)
        except ImportError as error:  # a bag without the optional rosbags package
            raise CLIError(f"{args.input}: {error}") from None
        n = len(sequence)
        if not 0 <= k < n - 1:
            last = f"0 to {n - 2}" if n > 1 else "none: it needs two frames"
            raise CLIError(
                f"{args.input}: --frame {k} registers frames {k} and {k + 1}, but it has "
                f"{n} frame(s) (--frame {last})"
            )
        first, second = sequence[k], sequence[k + 1]
    return sequence, first, second


def interval_between(first_stamp, second_stamp, where):
    """Seconds from the first timestamp to the second, or a CLIError naming ``where``."""
    if first_stamp is None or second_stamp is None:
        return None
    interval = second_stamp - first_stamp
    if not interval > 0:
        raise CLIError(
            f"{where}: the second sweep's timestamp ({second_stamp:.9f} s) is not after the "
            f"first's ({first_stamp:.9f} s); give --interval"
        )
    return interval


def check_time_range(times, interval, where):
    """``times`` within MAX_TIMES_PER_INTERVAL intervals of zero, or a CLIError."""
    import numpy as np

    largest = float(np.max(np.abs(times)))
    if largest > MAX_TIMES_PER_INTERVAL * interval:
        raise CLIError(
            f"{where}: capture times up to {largest:g} s from the reference time, more than "
            f"{MAX_TIMES_PER_INTERVAL:g} times --interval {interval:g} s; they must be "
            "seconds after the sweep's reference time (not nanoseconds, not absolute "
            "timestamps)"
        )
    return times


def file_timing(times, sweep_times, interval, where):
    """``fit``'s capture-time arguments from the times the files hold, or ``{}``.

    ``interval``: --interval, else the one the timestamps give (None when neither).
    All-zero times (files written without them) are no times.
    """
    import numpy as np

    if times is None or sweep_times is None:
        return {}
    if not (np.any(times) or np.any(sweep_times)):
        return {}
    if interval is None:
        raise CLIError(
            f"{where}: the sweeps hold capture times but no timestamps to tell the seconds "
            "between them; give --interval"
        )
    check_time_range(times, interval, where)
    check_time_range(sweep_times, interval, where)
    return {"times": times, "sweep_times": sweep_times, "interval": interval}
