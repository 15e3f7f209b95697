"""The bad rows real UR logs have (platform-notes.md: values of 1e300, rows cut short), put into a
recording's text, for the tests of ftc_hw.record.ur_csv."""
from __future__ import annotations


def with_bad_rows(text: str, *, at: int = 20) -> tuple[str, dict[str, int]]:
    """``text`` (a recording) with the bad rows real logs have put in after data row ``at``: a value of
    1e300, a NaN, a row cut short, a repeated timestamp (the previous row again). Returns the text and
    what the reader should count, by reason."""
    lines = text.splitlines(keepends=True)
    end = lines[1][len(lines[1].rstrip("\r\n")):]
    sep = "," if "," in lines[0] else " "
    row = lines[1 + at].rstrip("\r\n").split(sep)
    q0 = lines[0].split(sep).index("actual_q_0")
    huge, nan = list(row), list(row)
    huge[q0 + 1] = str(1e300) if sep == " " else f"{1e300:.6f}"  # as each writer prints 1e300
    nan[q0] = "nan"
    cut = sep.join(row[: len(row) // 2])
    bad = [sep.join(huge) + end, sep.join(nan) + end, cut + end, lines[1 + at]]
    lines[2 + at:2 + at] = bad
    return "".join(lines), {"out_of_range:actual_q": 1, "not_finite:actual_q": 1, "cut_short": 1, "time_repeated": 1}
