"""The command-line tools: ``geomdp-train`` (``train``), ``geomdp-plot`` (``plot``)
and ``geomdp-theory`` (``theory``)."""
