"""Recordings of a run: ``arroch record`` (one MCAP file Foxglove reads whole, and/or a ROS 2 bag),
``arroch view`` (the same channels live on the Foxglove WebSocket protocol), ``arroch replay`` (a
recording back onto Zenoh, byte for byte) and ``arroch runs show|export`` (a run's summary and
timeline; its recording as a ROS 2 bag)."""
