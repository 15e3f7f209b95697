"""The live 3-D page (``--view web``): the page's process on viser (``page``, ``scene``, its replay
player ``player``), the subscriber that feeds it (``feed``, ``state``), a recording's ticks (``replay``)."""
