"""Geo-objects: road files in (GeoJSON, GeoPackage, Shapefile, FlatGeobuf, OpenStreetMap), constant-HAL buffers
around the tolled roads out (build, check, info), and the compiled, memory-mapped store charging reads them from.

The room beside the readers: road data, as the readers are receiver data; it knows nothing of positions,
integrity or tariffs. Uses only the floor (errors, spatial, cache, io).
"""
