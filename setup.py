"""Build of the optional compiled kernels of the bulk NMEA reader, and the man pages' place (the rest is in pyproject.toml).

``optional=True``: where no C compiler is found the install goes on without them and
the reader uses the numpy versions of the same kernels (same tables, slower).
The man pages go to ``<prefix>/share/man/man1`` (a virtual environment's own ``share/man``: on MANPATH, ``man tollcli``
finds them).
"""

from glob import glob

from setuptools import Extension, setup

setup(
    data_files=[("share/man/man1", sorted(glob("man/*.1")))],
    ext_modules=[
        Extension(
            "tollcli.readers.nmea._bulk_kernels",
            ["tollcli/readers/nmea/_bulk_kernels.c"],
            extra_compile_args=["-O3"],
            optional=True,
        )
    ]
)
