// ParaView output: VTK XML unstructured grids (.vtu), one per frame and
// block, and a .pvd collection that gives each its time and its block (the
// body is part 0, each proxy a part of its own). Written by hand (the format
// is small and VTK is a heavy dependency): inline base64 binary arrays, each
// preceded by its byte count as UInt64, as VTK itself writes them.
//
// The body's points are its rest positions and `displacement` is the active
// vector: ParaView's Warp By Vector (scale 1) shows the deformed body, and
// every cell array is on the rest cells, as FEM post-processors have it. A
// proxy's points are where it is (it is rigid) with a zero `displacement`, so
// that warping the whole collection leaves it in place. The arrays and their
// units are listed in server/scenes/README.md.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/embedding.hpp"
#include "core/fields.hpp"
#include "core/mesh.hpp"
#include "core/proxy.hpp"
#include "core/spec.hpp"

namespace tactile {

// One frame of a body; node arrays (n_nodes x 3) in the mesh's numbering.
// Arrays left null are not written. With `body` set, only that body of a
// scene of several: its nodes and tets, in its own numbering (node i of the
// file is the body's node i), every array sliced to them.
struct VtuFrame {
  const TetMesh* mesh = nullptr;                // rest positions: the points written
  const std::vector<double>* u = nullptr;       // displacement [m]
  const std::vector<double>* v = nullptr;       // velocity [m/s]
  const std::vector<uint8_t>* fixed = nullptr;  // 0 free, 1 held in place, 2 moved by a prescribed motion (n_nodes)
  const std::vector<double>* contact_force = nullptr;   // mean contact force on the node over the frame [N]
  const std::vector<double>* energy_density = nullptr;  // strain-energy density per tet [J/m^3] (n_tets)
  const ElementFields* fields = nullptr;                // stress and strain per tet, those computed
  const BodySpec* body = nullptr;                       // null: the whole mesh
};

// Writes `path` (throws std::runtime_error when it cannot).
void write_vtu(const std::string& path, const VtuFrame& frame);

// A proxy's surface, triangulated in its pose: a Minkowski sum of its core
// (a point, a segment, a box) and a sphere of its radius, sampled over the
// directions of a cube's faces split `n` x `n` (n even, so that the core's
// flat faces and its edges are in the sample); a plane is a square of
// half-side `plane_half_size` about the proxy's origin.
struct ProxySurface {
  std::vector<double> points;      // world [m] (n_points x 3)
  std::vector<int32_t> triangles;  // (n_triangles x 3)
};
ProxySurface make_proxy_surface(const ProxyGeometry& g, const Pose& pose, double plane_half_size, int n = 8);

// One frame of a proxy: its surface, and the mean force and torque (about
// its position) on it over the frame's latest control interval, as field data.
struct VtuProxy {
  const ProxySurface* surface = nullptr;
  Vec3 force{0.0};   // [N]
  Vec3 torque{0.0};  // [N m]
  int32_t contacts = 0;
};
void write_vtu(const std::string& path, const VtuProxy& proxy);

// One frame of the fine surface a body carries (core/embedding.hpp): its
// rest vertices as points, and each vertex's displacement interpolated from
// its tet's nodes by its binding weights, so that Warp By Vector places it
// where the viewer draws it. Vertices as the scene loaded them (welded).
struct VtuSurface {
  const EmbeddedSurface* surface = nullptr;
  const std::vector<double>* u = nullptr;  // the body's node displacement [m] (n_nodes x 3)
  const BodySpec* body = nullptr;          // only its fine vertices and triangles (null: all)
};
void write_vtu(const std::string& path, const VtuSurface& surface);

struct PvdEntry {
  double t;          // [s]
  std::string file;  // relative to the .pvd
  int32_t part = 0;  // block: the bodies (0 for one), then proxy k, then the fine surfaces
  std::string name;  // the block's name ("" for none)
};
void write_pvd(const std::string& path, const std::vector<PvdEntry>& entries);

// RFC 4648 base64 (with padding), as VTK's binary arrays use.
std::string encode_base64(const void* data, size_t n_bytes);

}  // namespace tactile
