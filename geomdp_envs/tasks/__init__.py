"""The GeoMDP tasks, one module each."""
