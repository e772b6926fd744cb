"""The SUMO adapter: the only package that starts and steers SUMO (libsumo, its binaries,
sumo-gui, detector files, its outputs); :mod:`cosim.sumo.sublanes` (the sublane width
rule) is pure arithmetic on the road."""
