"""Build of the optional compiled kernels of the bulk NMEA reader (everything else is in pyproject.toml).

``optional=True``: where no C compiler is found the install goes on without them and
the reader uses the numpy versions of the same kernels (same tables, slower).
"""

from setuptools import Extension, setup

setup(
    ext_modules=[
        Extension(
            "tollcli.readers.nmea._bulk_kernels",
            ["tollcli/readers/nmea/_bulk_kernels.c"],
            extra_compile_args=["-O3"],
            optional=True,
        )
    ]
)
