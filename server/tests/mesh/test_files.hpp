// Shared helpers of the mesh tests: a per-test temporary folder, files
// written inline, and small geometric sums.
#pragma once

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include <unistd.h>

#include <glm/geometric.hpp>

#include "core/mesh.hpp"
#include "mesh/mesh_error.hpp"
#include "mesh/tetgen.hpp"

#include "temp_dir.hpp"

namespace tactile::test {

inline void write_file(const std::string& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out << bytes;
  ASSERT_TRUE(out.good()) << path;
}

// Appends the little-endian bytes of a trivially copyable value.
template <class T>
void put(std::string& bytes, T v) {
  bytes.append(reinterpret_cast<const char*>(&v), sizeof v);
}

// Expects `fn` to throw MeshError whose message contains every one of `parts`.
template <class Fn>
void expect_mesh_error(Fn&& fn, const std::vector<std::string>& parts) {
  try {
    fn();
    ADD_FAILURE() << "no MeshError thrown";
  } catch (const MeshError& e) {
    const std::string msg = e.what();
    for (const std::string& p : parts) EXPECT_NE(msg.find(p), std::string::npos) << "'" << p << "' not in: " << msg;
  }
}

inline double compute_mesh_volume(const TetMesh& m) {
  double v = 0.0;
  for (const Tet& t : m.tets)
    v += compute_tet_volume(m.X[size_t(t[0])], m.X[size_t(t[1])], m.X[size_t(t[2])], m.X[size_t(t[3])]);
  return v;
}

inline int count_nonpositive_tets(const TetMesh& m) {
  int n = 0;
  for (const Tet& t : m.tets)
    n += compute_tet_volume(m.X[size_t(t[0])], m.X[size_t(t[1])], m.X[size_t(t[2])], m.X[size_t(t[3])]) <= 0.0;
  return n;
}

// Number of edges of `tris` not shared by exactly two triangles.
inline int count_open_edges(const std::vector<Tri>& tris) {
  std::map<std::pair<int32_t, int32_t>, int> uses;
  for (const Tri& t : tris)
    for (size_t e = 0; e < 3; ++e) ++uses[std::minmax(t[e], t[(e + 1) % 3])];
  int bad = 0;
  for (const auto& [edge, n] : uses) bad += n != 2;
  return bad;
}

// Unit cube [0,1]^3: 8 corners (corner i has x = bit 0, y = bit 1, z = bit 2)
// and its 6 faces as quads, wound outwards.
inline std::vector<Vec3> cube_corners() {
  std::vector<Vec3> v;
  for (int i = 0; i < 8; ++i) v.emplace_back(i & 1, (i >> 1) & 1, (i >> 2) & 1);
  return v;
}
inline std::vector<std::array<int32_t, 4>> cube_quads() {
  return {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
}
inline SurfaceMesh make_cube_surface() {
  SurfaceMesh s;
  s.vertices = cube_corners();
  for (const auto& q : cube_quads()) {
    s.triangles.push_back({q[0], q[1], q[2]});
    s.triangles.push_back({q[0], q[2], q[3]});
  }
  return s;
}

}  // namespace tactile::test
