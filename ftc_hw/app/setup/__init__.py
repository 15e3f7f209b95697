"""What the other app packages share or run first: the rig builder (``rig``), the device probe
(``probe``), the kernels' warm-up (``warm``), vendor meshes (``vendor_meshes``) and the vendor
libraries' output made readable (``vendor_output``)."""
