"""Whether a path is a ROS 2 bag, told by its form (no ROS import, so that without the extra a bag is
still recognised and the user told what to install): a rosbag2 directory (``metadata.yaml``), an MCAP
file whose header's profile is ``ros2`` (ftc's own recordings have none), an sqlite3 file (``.db3``)."""
from __future__ import annotations

import struct
from pathlib import Path

MCAP_MAGIC = b"\x89MCAP0\r\n"
SQLITE_MAGIC = b"SQLite format 3\x00"
_HEADER_OP = 0x01


def mcap_profile(path: Path | str) -> str | None:
    """The profile an MCAP file's header record names ("" for none); None when it is not MCAP."""
    try:
        with open(path, "rb") as f:
            head = f.read(len(MCAP_MAGIC) + 9 + 4 + 256)
    except OSError:
        return None
    if not head.startswith(MCAP_MAGIC) or len(head) < len(MCAP_MAGIC) + 13:
        return None
    at = len(MCAP_MAGIC)
    if head[at] != _HEADER_OP:
        return None
    (n,) = struct.unpack_from("<I", head, at + 9)  # the record's opcode, its u64 length, then the profile
    return head[at + 13:at + 13 + n].decode("utf-8", errors="replace")


def is_ros_bag(path: Path | str) -> bool:
    """A rosbag2 directory, a ros2-profile MCAP file, or an sqlite3 ``.db3`` file."""
    path = Path(path)
    if path.is_dir():
        return (path / "metadata.yaml").is_file()
    if path.suffix == ".db3":
        try:
            with open(path, "rb") as f:
                return f.read(len(SQLITE_MAGIC)) == SQLITE_MAGIC
        except OSError:
            return False
    return mcap_profile(path) == "ros2"
