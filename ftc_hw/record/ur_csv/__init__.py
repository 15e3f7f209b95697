"""Users' UR recordings in: the CSV of UR's own RTDE client (``record.py``) and ur_rtde's file
recording, read into a typed :class:`URRecording` (docs/recording.md, "UR recordings in"); and a
writer of both formats (tests)."""
from .bounds import PhysicalBounds
from .errors import URCsvError
from .header import FORMAT_NAMES, UR_CLIENT, UR_RTDE
from .inputs import check_fits, pipeline_inputs
from .parse import parse_ur_csv
from .read import read_ur_csv, read_ur_csvs
from .recording import SENSING_OF, URRecording
from .timing import Timing
from .write import ur_csv_text, write_ur_csv

__all__ = ["FORMAT_NAMES", "SENSING_OF", "UR_CLIENT", "UR_RTDE", "PhysicalBounds", "Timing", "URCsvError",
           "URRecording", "check_fits", "parse_ur_csv", "pipeline_inputs", "read_ur_csv", "read_ur_csvs",
           "ur_csv_text", "write_ur_csv"]
