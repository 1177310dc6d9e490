#!/usr/bin/env python3
"""Reads a softshell render table (GET /geometries/{id}/render?level=L, binary) with nothing but
the standard library, evaluates the limit surface of the newest result (x = S P, normals from the
du/dv stencils) and writes it as an OBJ: what a thin client (Python, Unity C#) does per update.

    python3 docs/examples/render_table.py http://127.0.0.1:8080 GEOM_ID 2 > surface.obj
"""
import json
import math
import struct
import sys
import urllib.request


def get(url, accept="application/json"):
    with urllib.request.urlopen(urllib.request.Request(url, headers={"Accept": accept})) as r:
        return r.status, r.read()


def read_table(body):
    magic, version, level, control, nv, nq, nw, _flags = struct.unpack_from("<4s7I", body, 0)
    if magic != b"SSRT" or version != 1:
        raise ValueError("not a version-1 render table")
    at = 32
    def take(fmt, count):
        nonlocal at
        values = struct.unpack_from("<%d%s" % (count, fmt), body, at)
        at += 4 * count
        return values
    table = {"level": level, "control": control, "vertices": nv,
             "offsets": take("I", nv + 1), "indices": take("I", nw),
             "position": take("f", nw), "du": take("f", nw), "dv": take("f", nw)}
    quads = take("I", 8 * nq)
    table["quads"] = [quads[8 * q:8 * q + 8] for q in range(nq)]
    table["triangles"] = take("I", 6 * nq)
    if at != len(body):
        raise ValueError("trailing bytes")
    return table


def evaluate(table, control):
    """Limit positions and unit normals of the refined vertices for control positions [[x,y,z]]."""
    offsets, indices, w, wu, wv = (table[k] for k in ("offsets", "indices", "position", "du", "dv"))
    positions, normals = [], []
    for i in range(table["vertices"]):
        x = [0.0] * 3; xu = [0.0] * 3; xv = [0.0] * 3
        for k in range(offsets[i], offsets[i + 1]):
            p = control[indices[k]]
            for a in range(3):
                x[a] += w[k] * p[a]; xu[a] += wu[k] * p[a]; xv[a] += wv[k] * p[a]
        n = [xu[1] * xv[2] - xu[2] * xv[1], xu[2] * xv[0] - xu[0] * xv[2], xu[0] * xv[1] - xu[1] * xv[0]]
        length = math.sqrt(sum(c * c for c in n)) or 1.0
        positions.append(x)
        normals.append([c / length for c in n])
    return positions, normals


def main():
    base, geom_id, level = sys.argv[1].rstrip("/"), sys.argv[2], int(sys.argv[3]) if len(sys.argv) > 3 else 2
    _, body = get(f"{base}/geometries/{geom_id}/render?level={level}", "application/octet-stream")
    table = read_table(body)
    status, latest = get(f"{base}/geometries/{geom_id}/latest_result?wait=0")
    if status == 200:
        control = json.loads(latest)["positions"]
    else:  # no result yet: the rest shape
        _, geometry = get(f"{base}/geometries/{geom_id}")
        control = json.loads(geometry)["vertices"]
    positions, normals = evaluate(table, control)
    out = sys.stdout
    for p in positions:
        out.write("v %.9g %.9g %.9g\n" % tuple(p))
    for n in normals:
        out.write("vn %.6f %.6f %.6f\n" % tuple(n))
    t = table["triangles"]
    for i in range(0, len(t), 3):
        a, b, c = t[i] + 1, t[i + 1] + 1, t[i + 2] + 1
        out.write(f"f {a}//{a} {b}//{b} {c}//{c}\n")


if __name__ == "__main__":
    main()
