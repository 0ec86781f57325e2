"""VMC over OSC: the parser and frame assembler (``codec``), Unity bone names (``bones``),
the assembly rules (``frames``), whole-frame datagram templates (``template``) and the
reference encoder (``encode``).

May import ``rtseg.core``, ``rtseg.drivers.base`` and ``rtseg.drivers.osc.codec``."""
