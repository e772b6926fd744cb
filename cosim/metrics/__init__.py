"""What a run measures, from the road-frame snapshots the loop records: traffic
(:mod:`~cosim.metrics.traffic`: Edie flow, gaps, TTC, collisions, boundary violations),
jams (:mod:`~cosim.metrics.jams`: standstills, blocked windows), capacity
(:mod:`~cosim.metrics.capacity`: the active bottleneck and its discharge flow) and flock
metrics (:mod:`~cosim.metrics.flock`); :mod:`~cosim.metrics.kernels` holds their compiled
inner loops. No SUMO here."""
