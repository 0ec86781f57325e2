"""Sources that replay motion in-process: a recorded take (``file``, ``file://``), the
procedural synthesiser (``sim``, ``sim://``) and the absolute-schedule pacing both share
(``pacing``).

May import ``rtseg.core``, ``rtseg.drivers.base``, ``rtseg.drivers.options``,
``rtseg.drivers.readers`` and ``rtseg.simulators.synth``."""
