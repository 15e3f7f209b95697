"""The devices served on Zenoh (``ftc serve``: readers in supervised processes), a monitor's rig of
frames from reader processes (``remote_rig``), a recorder on Zenoh (``ftc record --remote``)."""
