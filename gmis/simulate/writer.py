"""Dataset writer: the folder layout of docs/formats.md, written atomically.

Everything is built in a hidden temporary sibling folder and moved into place with
os.replace only when every file has been written, so a failure leaves no partial dataset.
"""

import json
import math
import os
import shutil
import tempfile

import numpy as np

from gmis.errors import GmisInputError

RAD2DEG = 180.0 / np.pi

IMU_HEADER = "time_gps_s,gyro_x,gyro_y,gyro_z,accel_x,accel_y,accel_z"
GNSS_HEADER = ("time_gps_s,lat_deg,lon_deg,h_m,sigma_e_m,sigma_n_m,sigma_u_m,"
               "ve_m_s,vn_m_s,vu_m_s,sigma_ve_m_s,sigma_vn_m_s,sigma_vu_m_s")
HEADING_HEADER = "time_gps_s,heading_deg,sigma_heading_deg"
REFERENCE_HEADER = ("time_gps_s,lat_deg,lon_deg,h_m,ve_m_s,vn_m_s,vu_m_s,"
                    "pitch_deg,roll_deg,heading_deg")


def write_csv(path, header, columns, formats, comment=None):
    """Write equal-length 1-D columns with one printf format each (fast path: one
    vectorised % per row block through numpy.savetxt)."""
    data = np.column_stack(columns)
    head = (f"# {comment}\n" if comment else "") + header
    with open(path, "w", newline="\n") as fh:
        fh.write(head + "\n")
        np.savetxt(fh, data, fmt=formats, delimiter=",")


def _toml_value(value):
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ValueError(f"cannot write {value} to TOML")
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, np.generic):
        return _toml_value(value.item())
    raise TypeError(f"cannot write {type(value).__name__} to TOML")


def dump_toml(doc, comments=None):
    """Serialise a dict of tables (values: scalars, lists, nested tables, lists of tables).
    comments: optional {table name: comment line(s)} written above the table."""
    comments = comments or {}
    lines = []

    def table(name, body, array=False):
        if name in comments:
            lines.extend(f"# {c}" for c in comments[name].splitlines())
        lines.append(f"[[{name}]]" if array else f"[{name}]")
        subtables = []
        for key, value in body.items():
            if isinstance(value, dict):
                subtables.append((f"{name}.{key}", value, False))
            elif isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
                subtables.extend((f"{name}.{key}", v, True) for v in value)
            else:
                lines.append(f"{key} = {_toml_value(value)}")
        lines.append("")
        for sub in subtables:
            table(*sub)

    for name, body in doc.items():
        if isinstance(body, list):
            for item in body:
                table(name, item, array=True)
        else:
            table(name, body)
    return "\n".join(lines)


def prepare_output_dir(out_dir, overwrite):
    """Validate the destination and return a fresh temporary sibling folder."""
    out_dir = os.path.abspath(os.fspath(out_dir))
    parent = os.path.dirname(out_dir)
    if os.path.exists(out_dir):
        if not os.path.isdir(out_dir):
            raise GmisInputError("output path exists and is not a folder", out_dir)
        if os.listdir(out_dir) and not overwrite:
            raise GmisInputError("output folder exists and is not empty (use overwrite)",
                                 out_dir)
    os.makedirs(parent, exist_ok=True)
    tmp = tempfile.mkdtemp(prefix=f".{os.path.basename(out_dir)}.tmp-", dir=parent)
    umask = os.umask(0o022)
    os.umask(umask)
    os.chmod(tmp, 0o777 & ~umask)  # mkdtemp makes 0700; a dataset is an ordinary folder
    return out_dir, tmp


def commit_output_dir(tmp_dir, out_dir):
    """Move the finished temporary folder into place (replacing an old dataset)."""
    old = None
    if os.path.exists(out_dir):
        old = tempfile.mkdtemp(prefix=f".{os.path.basename(out_dir)}.old-",
                               dir=os.path.dirname(out_dir))
        os.replace(out_dir, os.path.join(old, "data"))
    os.replace(tmp_dir, out_dir)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)
