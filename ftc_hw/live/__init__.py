"""The live monitor's run: emulated world (``simworld``), session, live view, events, evaluation against truth."""
