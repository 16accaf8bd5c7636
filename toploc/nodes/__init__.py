"""The nodes of toploc on the Zenoh bus: each serves one package's objects under
``toploc/<robot_id>/`` through the contract of :mod:`toploc.bus`."""
