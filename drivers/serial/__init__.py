"""Serial IMU suits (USB CDC / UART): rtseg's wire format (``wire``: constants, COBS/CRC
framing, encoder), its streaming decoders (``codec`` binary, ``text`` lines, ``decoded``
the checks both share), the live source (``source``) and its URL ``serial://`` (``url``).

May import ``rtseg.core``, ``rtseg.drivers.base`` and ``rtseg.drivers.options``."""
