"""What talks to each node over the bus, apart from the nodes (:mod:`toploc.nodes`) that serve
the keys: :mod:`~toploc.bus.clients.robot` (a Robot whose calls go over the bus),
:mod:`~toploc.bus.clients.localizer`, :mod:`~toploc.bus.clients.mapdb`,
:mod:`~toploc.bus.clients.homing`, :mod:`~toploc.bus.clients.site_map` (a site's shared map and
its replication), and :mod:`~toploc.bus.clients.sim_truth` (simulation only);
:mod:`~toploc.bus.clients.base` holds what they share."""
