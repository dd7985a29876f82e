#!/usr/bin/env python3
"""Writes the binary PLY files of the catalogue (files/binary/*.ply): binary data needs real bytes,
so they are made here rather than by hand. Run it from anywhere after changing a file below; the
output is committed beside it."""
import math
import os
import struct

HERE = os.path.join(os.path.dirname(os.path.abspath(__file__)), 'binary')
CODES = {'char': 'b', 'uchar': 'B', 'short': 'h', 'ushort': 'H', 'int': 'i', 'uint': 'I',
         'float': 'f', 'double': 'd'}
NAN, INF = math.nan, math.inf
XYZ = [('float', 'x'), ('float', 'y'), ('float', 'z')]
ROWS3 = [(0.0, 0.5, 0.0), (0.1, 0.5, 0.0), (0.2, 0.5, 0.0)]


def ply(vertex_props, vertex_rows, big=False, count=None, edges=None, cut=0):
    """A binary PLY: `count` overrides the vertex count written in the header; `edges` is
    (props, rows) for an edge element; `cut` drops that many bytes from the end."""
    order = '>' if big else '<'
    head = 'ply\nformat binary_%s_endian 1.0\n' % ('big' if big else 'little')
    head += 'element vertex %d\n' % (len(vertex_rows) if count is None else count)
    head += ''.join('property %s %s\n' % p for p in vertex_props)
    body = b''.join(struct.pack(order + ''.join(CODES[t] for t, _ in vertex_props), *r)
                    for r in vertex_rows)
    if edges:
        props, rows = edges
        head += 'element edge %d\n' % len(rows)
        head += ''.join('property %s %s\n' % p for p in props)
        body += b''.join(struct.pack(order + ''.join(CODES[t] for t, _ in props), *r) for r in rows)
    data = (head + 'end_header\n').encode() + body
    return data[:len(data) - cut] if cut else data


EDGE = [('int', 'vertex1'), ('int', 'vertex2'), ('float', 'restlength')]
FILES = {
    'ok.ply': ply(XYZ, ROWS3),
    'ok_big_endian.ply': ply(XYZ, ROWS3, big=True),
    'x_nan.ply': ply(XYZ, [ROWS3[0], (NAN, 0.5, 0.0), ROWS3[2]]),
    'y_nan.ply': ply(XYZ, [ROWS3[0], (0.1, NAN, 0.0), ROWS3[2]]),
    'z_inf.ply': ply(XYZ, [ROWS3[0], (0.1, 0.5, INF), ROWS3[2]]),
    'y_minus_inf_big_endian.ply': ply(XYZ, [ROWS3[0], (0.1, -INF, 0.0), ROWS3[2]], big=True),
    'double_y_1e300.ply': ply([('double', 'x'), ('double', 'y'), ('double', 'z')],
                              [(0.0, 1e300, 0.0)]),
    'double_z_nan.ply': ply([('double', 'x'), ('double', 'y'), ('double', 'z')],
                            [(0.0, 0.5, NAN)]),
    'pscale_nan.ply': ply(XYZ + [('float', 'pscale')], [(0.0, 0.5, 0.0, NAN)]),
    'v_inf.ply': ply(XYZ + [('float', 'vx'), ('float', 'vy'), ('float', 'vz')],
                     [(0.0, 0.5, 0.0, 0.0, INF, 0.0)]),
    'restlength_nan.ply': ply(XYZ, ROWS3[:2], edges=(EDGE, [(0, 1, NAN)])),
    'restlength_inf_big_endian.ply': ply(XYZ, ROWS3[:2], big=True, edges=(EDGE, [(0, 1, INF)])),
    'edge_vertex_out_of_range.ply': ply(XYZ, ROWS3[:2], edges=(EDGE, [(0, 7, 0.1)])),
    'truncated_vertex.ply': ply(XYZ, ROWS3, cut=5),
    'truncated_edge.ply': ply(XYZ, ROWS3[:2], edges=(EDGE, [(0, 1, 0.1)]), cut=2),
    'count_lies_more.ply': ply(XYZ, ROWS3, count=4),
    'count_4e9.ply': ply(XYZ, ROWS3, count=4000000000),
    'count_1e9.ply': ply(XYZ, ROWS3, count=1000000000),
    # a list that says 255 items follow, and none do
    'list_length_255.ply': ply(XYZ + [('uchar', 'n')], [(0.0, 0.5, 0.0, 255)]).replace(
        b'property uchar n', b'property list uchar int idx'),
    'id_uint_huge.ply': ply(XYZ + [('uint', 'id')], [(0.0, 0.5, 0.0, 4294967295),
                                                     (0.1, 0.5, 0.0, 7)]),
}

if __name__ == '__main__':
    os.makedirs(HERE, exist_ok=True)
    for name, data in FILES.items():
        with open(os.path.join(HERE, name), 'wb') as f:
            f.write(data)
    print('wrote %d files in %s' % (len(FILES), HERE))
