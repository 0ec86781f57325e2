"""Simulated devices, for tests and demos without a suit (installed as
``rtseg.simulators``): the procedural motion synthesiser (``synth``), a serial IMU suit on
a real pseudo-terminal (``serial_device``), senders that replay a take over the network as
a VMC performer (``vmc_sender``), Rokoko Studio, Axis Neuron, Xsens MVN and Sony mocopi
(``*_sender``, sharing ``stream_sender`` / ``udp_take_sender``), the retargeting of a take
onto a suit's sensors (``retarget``) and deterministic fault injection (``faults``).

May import ``rtseg.core``, ``rtseg.drivers`` (the codecs whose bytes
they send, the take readers) and ``rtseg.cli`` (in the ``main()`` of a ``python -m`` entry
point only)."""
