"""Serial IMU suits (USB CDC / UART): rtseg's wire format (``wire``: constants, COBS/CRC
framing, encoder), its streaming decoders (``codec`` binary, ``text`` lines, ``decoded``
the checks both share) and the live source ``serial://`` (``source``).

May import ``rtseg.core``, ``rtseg.drivers.base`` and ``rtseg.drivers.options``."""
