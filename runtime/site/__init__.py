"""Site tools: the top-down render, ``arroch site`` and the generators of site files.

The site model itself (loading, validation, geometry, occupancy grid) is :mod:`protocol.site`.
"""
