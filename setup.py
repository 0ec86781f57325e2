"""The one part of the build pyproject.toml cannot say: the optional C kernel of the Axis
decoder (``drivers/axis/_axis_kernel.c`` -> ``rtseg.drivers.axis._axis_kernel``).  ``optional``: where
no C compiler or Python headers are available the install goes on without it and
``rtseg.drivers.axis.codec`` uses its numpy path (the same local quaternions; global ones
within 1e-15)."""

from setuptools import Extension, setup

setup(ext_modules=[Extension("rtseg.drivers.axis._axis_kernel", ["drivers/axis/_axis_kernel.c"],
                             optional=True)])
