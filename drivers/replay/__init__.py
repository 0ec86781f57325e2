"""Sources that replay motion in-process: a recorded take (``file``, ``file://``), the
procedural synthesiser (``sim``, ``sim://``) and the absolute-schedule pacing both share
(``pacing``)."""
