"""The engine-adapter SDK, as ``realitygap.engine``: the same module as
``realitygap_engine``, which this package also installs.

An adapter runs in its engine's own environment, where this package need
not be installed, so adapters import ``realitygap_engine`` itself (numpy
and the standard library only; realitygap puts it on the child's
``PYTHONPATH``). Here it serves code that has the package already: tests
of an adapter, tools around one::

    import realitygap.engine as rge

    class MyEngine(rge.Adapter): ...

See ``docs/engine-protocol.md`` ("Writing an adapter in Python").
"""

from realitygap_engine import *  # noqa: F401,F403
from realitygap_engine import __all__  # noqa: F401
