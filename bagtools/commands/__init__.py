"""The commands: one module or package per ``bagtools`` command, named as the command is.

``info`` (``bagtools info``), ``grid``, ``map_cloud`` (``map-cloud``), ``ndt_odom`` (``ndt-odom``), ``slam``,
``localize`` and ``export``: each holds its command's own pipeline over a bag, its options and its writer, on top of
the shared layers below (``odometry``, ``pose_graph``, ``grid``, ``cloud``, ``dataset``, ...). A command never imports
another: what two of them share belongs below them (``docs/architecture.md``). Their click commands are in
:mod:`bagtools.cli`, with the same names.
"""
