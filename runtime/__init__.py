"""What ARROCH's processes run alike: the code behind the contracts of :mod:`protocol`.

``protocol`` is the typed wire (messages, keys, the codec, the site model and its schema, the ASP
vocabulary, the constraint library's types) and imports only the standard library, msgspec and
numpy. Everything a process needs to *use* that wire lives here: the ``Service`` framework and its
transport, clocks and stop signals, process launching, certificates, the feedback client, the
executors' controllers and geometry, camera frames and tags, ROS 2 on Zenoh, the site tools and
the ``ping``/``router`` commands. ``runtime`` imports ``protocol``, never a service.
"""
