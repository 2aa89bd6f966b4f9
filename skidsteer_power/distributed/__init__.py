"""Running studies on Dask: an embedded LocalCluster or an existing cluster (:mod:`.engine`)."""
