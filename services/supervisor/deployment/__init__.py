"""``arroch deploy``: TLS certificates (:mod:`.certs`), the access-control policy (:mod:`.acl`) and
per-host Zenoh configs rendered from ``deploy/zenoh/`` templates (:mod:`.render`)."""
