"""MCAP recording of the bus (``writer``), reading (``reader``, also of a cut file) and replay (``replay``)."""
