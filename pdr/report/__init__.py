"""Outputs of ``pdr run``: CSV tables, summary/provenance JSON, GeoJSON, TUM, GPX and the PNG plots."""

from pdr.io.tomlio import dumps_json, jsonable
from pdr.report.plot import write_bouts_plot, write_plot
from pdr.report.writers import (
    geojson_object,
    gpx_text,
    steps_table,
    trajectory_table,
    tum_text,
    write_bouts_csv,
    write_geojson,
    write_gpx,
    write_json,
    write_steps_csv,
    write_strides_csv,
    write_trajectory_csv,
    write_tum,
    yaw_to_quaternion_xyzw,
)

__all__ = [
    "dumps_json", "geojson_object", "gpx_text", "jsonable", "steps_table", "trajectory_table", "tum_text", "write_bouts_csv",
    "write_bouts_plot", "write_geojson", "write_gpx", "write_json", "write_plot", "write_steps_csv", "write_strides_csv", "write_trajectory_csv", "write_tum",
    "yaw_to_quaternion_xyzw",
]
