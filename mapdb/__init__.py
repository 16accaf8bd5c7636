"""The SQLite map: rooms, room graph, places and fingerprints.

The map is topological: each room has its own metric frame; a place's ``x_m``, ``y_m`` and
``heading_deg`` are in the frame of its room. Import what you need from its modules (this file
imports nothing, so that ``mapdb.records`` stays free of SQLite):

- ``mapdb.records``: the pure records (``Place``, ``Fingerprint``, ``FingerprintTable``, ...).
- ``mapdb.database.MapDatabase`` (``MapDatabase.open(path)``): rooms, edges, places, ``add_place``.
- ``mapdb.loading``: every fingerprint in one query, or the whole map as a ``MapSnapshot``.
- ``mapdb.graph``: the room graph as networkx / GraphML.
- ``mapdb.dataset`` + ``mapdb.build``: import a dataset folder with an injected extractor.
- ``mapdb.workers``: the spawned process pool every parallel step of toploc uses.
- ``mapdb.errors``: every failure, naming the file, room or column.
"""
