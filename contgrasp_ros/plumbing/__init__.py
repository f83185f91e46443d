"""The message plumbing the nodes share: message conversions (typed and CDR), QoS, topic names,
markers, the lean executor and the node runtime; plain calls into :mod:`contgrasp_core`."""
