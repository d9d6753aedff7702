#!/usr/bin/env python3
"""Write CDR reference encodings made by an independent implementation (rosbags).

sepmem's tests (tests/wire_cdr.rs) build the very same message values in Rust,
encode them with sepmem's codec and compare the bytes with these files, then
decode these files and compare the values. Run from the repository root:

    python3 tests/python/make_cdr_fixtures.py

Outputs (committed): tests/data/cdr/*.cdr and tests/data/cdr/rosbags_types.json
(RIHS01 hash and concatenated definition of every type, as rosbags computes them).
"""

import json
import pathlib

import numpy as np
from rosbags.typesys import Stores, get_typestore, get_types_from_msg

ROOT = pathlib.Path(__file__).resolve().parents[2]
OUT = ROOT / 'tests' / 'data' / 'cdr'

ts = get_typestore(Stores.ROS2_JAZZY)
own = {}
for name in ('SurfaceMesh', 'FrameDiagnostics', 'GroundTruth'):
    text = (ROOT / 'msg' / 'msg' / f'{name}.msg').read_text()
    own.update(get_types_from_msg(text, f'sepmem_msgs/msg/{name}'))
for name in ('moveit_msgs/msg/CollisionObject', 'object_recognition_msgs/msg/ObjectType'):
    pkg, _, ty = name.split('/')
    text = (ROOT / 'msg' / 'third_party' / pkg / 'msg' / f'{ty}.msg').read_text()
    own.update(get_types_from_msg(text, name))
ts.register(own)

T = ts.types
Time = T['builtin_interfaces/msg/Time']
Duration = T['builtin_interfaces/msg/Duration']
Header = T['std_msgs/msg/Header']
ColorRGBA = T['std_msgs/msg/ColorRGBA']
PointField = T['sensor_msgs/msg/PointField']
PointCloud2 = T['sensor_msgs/msg/PointCloud2']
CompressedImage = T['sensor_msgs/msg/CompressedImage']
Point = T['geometry_msgs/msg/Point']
Quaternion = T['geometry_msgs/msg/Quaternion']
Pose = T['geometry_msgs/msg/Pose']
Vector3 = T['geometry_msgs/msg/Vector3']
Marker = T['visualization_msgs/msg/Marker']
MarkerArray = T['visualization_msgs/msg/MarkerArray']
MeshFile = T['visualization_msgs/msg/MeshFile']
Mesh = T['shape_msgs/msg/Mesh']
MeshTriangle = T['shape_msgs/msg/MeshTriangle']
KeyValue = T['diagnostic_msgs/msg/KeyValue']
DiagnosticStatus = T['diagnostic_msgs/msg/DiagnosticStatus']
DiagnosticArray = T['diagnostic_msgs/msg/DiagnosticArray']
SurfaceMesh = T['sepmem_msgs/msg/SurfaceMesh']
FrameDiagnostics = T['sepmem_msgs/msg/FrameDiagnostics']
GroundTruth = T['sepmem_msgs/msg/GroundTruth']

u8 = lambda xs: np.array(xs, dtype=np.uint8)  # noqa: E731


def header(sec, nsec, frame):
    return Header(stamp=Time(sec=sec, nanosec=nsec), frame_id=frame)


def pc2_xyzrgb():
    # 3 points, x y z float32 at 0/4/8, rgb packed float32 at 12, point_step 16.
    data = u8([(i * 7 + 3) % 256 for i in range(48)])
    fields = [PointField(name=n, offset=o, datatype=7, count=1)
              for n, o in (('x', 0), ('y', 4), ('z', 8), ('rgb', 12))]
    return PointCloud2(header=header(12, 345, 'map'), height=1, width=3, fields=fields,
                       is_bigendian=False, point_step=16, row_step=48, data=data, is_dense=True)


def pc2_utf8():
    # Non-ASCII frame id (UTF-8 on the wire), organised 2x2, float64 xyz + uint8 label.
    data = u8([(i * 13 + 1) % 256 for i in range(4 * 32)])
    fields = [PointField(name='z', offset=16, datatype=8, count=1),
              PointField(name='x', offset=0, datatype=8, count=1),
              PointField(name='y', offset=8, datatype=8, count=1),
              PointField(name='label', offset=24, datatype=2, count=1)]
    return PointCloud2(header=header(-5, 999999999, 'caméra_ß'), height=2, width=2, fields=fields,
                       is_bigendian=False, point_step=32, row_step=64, data=data, is_dense=False)


def marker_array():
    delete_all = Marker(header=header(1, 2, 'map'), ns='', id=0, type=0, action=3,
                        pose=Pose(position=Point(x=0.0, y=0.0, z=0.0),
                                  orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)),
                        scale=Vector3(x=0.0, y=0.0, z=0.0),
                        color=ColorRGBA(r=0.0, g=0.0, b=0.0, a=0.0),
                        lifetime=Duration(sec=0, nanosec=0), frame_locked=False,
                        points=[], colors=[], texture_resource='',
                        texture=CompressedImage(header=header(0, 0, ''), format='', data=u8([])),
                        uv_coordinates=[], text='', mesh_resource='',
                        mesh_file=MeshFile(filename='', data=u8([])),
                        mesh_use_embedded_materials=False)
    tri = Marker(header=header(1, 2, 'map'), ns='sepmem', id=7, type=11, action=0,
                 pose=Pose(position=Point(x=0.0, y=0.0, z=0.0),
                           orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)),
                 scale=Vector3(x=1.0, y=1.0, z=1.0),
                 color=ColorRGBA(r=0.2, g=0.6, b=1.0, a=0.8),
                 lifetime=Duration(sec=0, nanosec=500000000), frame_locked=False,
                 points=[Point(x=0.0, y=0.0, z=0.0), Point(x=1.0, y=0.0, z=0.0),
                         Point(x=0.0, y=1.0, z=0.5)],
                 colors=[ColorRGBA(r=1.0, g=0.0, b=0.0, a=1.0),
                         ColorRGBA(r=0.0, g=1.0, b=0.0, a=1.0),
                         ColorRGBA(r=0.0, g=0.0, b=1.0, a=1.0)],
                 texture_resource='',
                 texture=CompressedImage(header=header(0, 0, ''), format='', data=u8([])),
                 uv_coordinates=[], text='', mesh_resource='',
                 mesh_file=MeshFile(filename='', data=u8([])),
                 mesh_use_embedded_materials=False)
    return MarkerArray(markers=[delete_all, tri])


def diagnostic_array():
    st = [DiagnosticStatus(level=0, name='sepmem: stream /seg/points', message='warm',
                           hardware_id='host1',
                           values=[KeyValue(key='eta_g', value='0.912'),
                                   KeyValue(key='iterations', value='4')]),
          DiagnosticStatus(level=2, name='sepmem: stream /seg/points#3', message='cold: eta drop',
                           hardware_id='host1', values=[])]
    return DiagnosticArray(header=header(100, 5, ''), status=st)


def mesh():
    return Mesh(triangles=[MeshTriangle(vertex_indices=np.array([0, 1, 2], dtype=np.uint32)),
                           MeshTriangle(vertex_indices=np.array([0, 2, 3], dtype=np.uint32))],
                vertices=[Point(x=0.0, y=0.0, z=0.0), Point(x=1.0, y=0.0, z=0.0),
                          Point(x=1.0, y=1.0, z=0.0), Point(x=0.25, y=-1.5, z=2.0)])


def surface_mesh():
    return SurfaceMesh(header=header(7, 8, 'base_link'), stream_id='/seg/points#3', object_id=3,
                       vertices=[Point(x=0.5, y=0.0, z=0.0), Point(x=0.0, y=0.5, z=0.0),
                                 Point(x=0.0, y=0.0, z=0.5)],
                       triangles=[MeshTriangle(vertex_indices=np.array([0, 1, 2], dtype=np.uint32))],
                       vertex_separability=np.array([0.25, 0.5, 0.75], dtype=np.float32),
                       global_separability=0.875, grid_m=16, grid_l=9, iterations=12,
                       warm_start=True, start_reason='previous_surface', stop_reason='converged',
                       quality=3)


def collision_object():
    C = T['moveit_msgs/msg/CollisionObject']
    Prim = T['shape_msgs/msg/SolidPrimitive']
    Polygon = T['geometry_msgs/msg/Polygon']
    Point32 = T['geometry_msgs/msg/Point32']
    Plane = T['shape_msgs/msg/Plane']
    ObjectType = T['object_recognition_msgs/msg/ObjectType']
    pose = Pose(position=Point(x=0.1, y=-0.2, z=1.5), orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0))
    return C(header=header(7, 8, 'camera'), pose=pose, id='sepmem/seg/points#3',
             type=ObjectType(key='k', db=''),
             primitives=[Prim(type=1, dimensions=np.array([0.1, 0.2, 0.3]),
                              polygon=Polygon(points=[Point32(x=1.0, y=2.0, z=3.0)]))],
             primitive_poses=[pose], meshes=[mesh()], mesh_poses=[pose],
             planes=[Plane(coef=np.array([0.0, 0.0, 1.0, -0.5]))], plane_poses=[pose],
             subframe_names=['tip'], subframe_poses=[pose], operation=0)


def frame_diagnostics():
    return FrameDiagnostics(header=header(7, 8, 'base_link'), stream_id='/seg/points#3',
                            frame_index=41, points_in=20000, points_used=19876, points_dropped=124,
                            iterations=12, global_separability=0.875, latency_ms=6.5,
                            warm_start=False, start_reason='first_frame', stop_reason='iteration_cap')


def ground_truth():
    return GroundTruth(header=header(7, 8, 'camera'), stream_id='/synth/points#2', mesh_id='torus',
                       pose=Pose(position=Point(x=0.1, y=-0.2, z=1.5),
                                 orientation=Quaternion(x=0.0, y=0.0, z=0.6, w=0.8)),
                       world_frame_id='world',
                       camera_pose=Pose(position=Point(x=-0.5, y=0.25, z=0.125),
                                        orientation=Quaternion(x=0.6, y=0.0, z=0.0, w=0.8)),
                       width=640, height=480, fx=525.0, fy=526.5, cx=319.5, cy=239.25,
                       visible_points=1234,
                       vertices=[Point(x=0.5, y=0.0, z=0.0), Point(x=0.0, y=0.5, z=0.0),
                                 Point(x=0.0, y=0.0, z=0.5)],
                       triangles=[MeshTriangle(vertex_indices=np.array([0, 2, 1], dtype=np.uint32))])


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    samples = [
        ('pointcloud2_xyzrgb', pc2_xyzrgb(), True),
        ('pointcloud2_utf8_organised', pc2_utf8(), True),
        ('pointcloud2_utf8_organised_be', pc2_utf8(), False),
        ('marker_array', marker_array(), True),
        ('diagnostic_array', diagnostic_array(), True),
        ('mesh', mesh(), True),
        ('surface_mesh', surface_mesh(), True),
        ('frame_diagnostics', frame_diagnostics(), True),
        ('ground_truth', ground_truth(), True),
        ('collision_object', collision_object(), True),
    ]
    for name, msg, le in samples:
        data = bytes(ts.serialize_cdr(msg, msg.__msgtype__, little_endian=le))
        back = ts.deserialize_cdr(data, msg.__msgtype__)
        assert type(back) is type(msg)
        (OUT / f'{name}.cdr').write_bytes(data)
        print(f'{name}.cdr: {msg.__msgtype__}, {len(data)} bytes')
    types = sorted(set(ts.types) & {
        'builtin_interfaces/msg/Time', 'builtin_interfaces/msg/Duration', 'std_msgs/msg/Header',
        'std_msgs/msg/ColorRGBA', 'sensor_msgs/msg/PointField', 'sensor_msgs/msg/PointCloud2',
        'sensor_msgs/msg/CompressedImage', 'geometry_msgs/msg/Point', 'geometry_msgs/msg/Pose',
        'geometry_msgs/msg/Quaternion', 'geometry_msgs/msg/Vector3',
        'visualization_msgs/msg/Marker', 'visualization_msgs/msg/MarkerArray',
        'visualization_msgs/msg/UVCoordinate', 'visualization_msgs/msg/MeshFile',
        'shape_msgs/msg/Mesh', 'shape_msgs/msg/MeshTriangle', 'diagnostic_msgs/msg/KeyValue',
        'diagnostic_msgs/msg/DiagnosticStatus', 'diagnostic_msgs/msg/DiagnosticArray',
        'sepmem_msgs/msg/SurfaceMesh', 'sepmem_msgs/msg/FrameDiagnostics',
        'sepmem_msgs/msg/GroundTruth', 'geometry_msgs/msg/Point32', 'geometry_msgs/msg/Polygon',
        'shape_msgs/msg/SolidPrimitive', 'shape_msgs/msg/Plane', 'object_recognition_msgs/msg/ObjectType',
        'moveit_msgs/msg/CollisionObject'})
    table = {t: {'rihs01': ts.hash_rihs01(t), 'msgdef': ts.generate_msgdef(t, ros_version=2)[0]}
             for t in types}
    (OUT / 'rosbags_types.json').write_text(json.dumps(table, indent=1, sort_keys=True) + '\n')
    print(f'rosbags_types.json: {len(table)} types')


if __name__ == '__main__':
    main()
