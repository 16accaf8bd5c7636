"""toploc: probabilistic topological localization for mobile robots.

This package is the thin application shell: the ``toploc`` command line and (later) the Zenoh bus
contract. The domain lives in the sibling packages ``homing``, ``localizer``, ``mapdb`` and
``robot``.
"""

__version__ = "0.1.0"
