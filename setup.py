"""Build of the optional compiled kernels (the bulk NMEA reader's, the CSV writer's rows, the trajectory filter's pass), and the man pages'
place (the rest is in pyproject.toml).

``optional=True``: where no C compiler is found the install goes on without them and
the package uses the Python versions of the same kernels (same results, slower). The trajectory kernel is built
with ``-ffp-contract=off``: no fused multiply-add, so that its sums and products round as the Python twin's do.
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
        ),
        Extension(
            "tollcli.io._csv_kernel",
            ["tollcli/io/_csv_kernel.c"],
            extra_compile_args=["-O3", "-ffp-contract=off"],
            optional=True,
        ),
        Extension(
            "tollcli.integrity._trajectory_kernel",
            ["tollcli/integrity/_trajectory_kernel.c"],
            extra_compile_args=["-O3", "-ffp-contract=off", "-fno-fast-math"],
            optional=True,
        ),
    ]
)
