#include "mesh/mesh_io.hpp"

#include <gtest/gtest.h>

#include <cstdint>
#include <sstream>
#include <string>

#include "core/quadratic.hpp"
#include "mesh/primitives.hpp"
#include "mesh/test_files.hpp"

namespace tactile {
namespace {

using test::cube_quads;
using test::expect_mesh_error;
using test::put;
using test::TempDir;
using test::write_file;

// The test cube [-1, 1] x [0, 0.5] x [2, 2.25] (volume 0.25): values exact in
// float, so every format, Assimp's single precision included, reads them exactly.
const Vec3 kLo(-1.0, 0.0, 2.0), kHi(1.0, 0.5, 2.25);
constexpr double kCubeVolume = 0.25;

std::vector<Vec3> corners() {
  std::vector<Vec3> v;
  for (const Vec3& u : test::cube_corners()) v.push_back(kLo + u * (kHi - kLo));
  return v;
}

std::string num(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.17g", v);
  return buf;
}

std::string vertex_line(const Vec3& p) { return num(p.x) + " " + num(p.y) + " " + num(p.z); }

// The cube in each format, polygons as quads where the format allows them.
std::string cube_obj() {
  std::string s = "# cube\no cube\n";
  for (const Vec3& p : corners()) s += "v " + vertex_line(p) + "\n";
  for (const auto& q : cube_quads())
    s += "f " + std::to_string(q[0] + 1) + " " + std::to_string(q[1] + 1) + " " + std::to_string(q[2] + 1) + " " +
         std::to_string(q[3] + 1) + "\n";
  return s;
}

std::vector<std::array<Vec3, 3>> cube_triangles() {
  const std::vector<Vec3> v = corners();
  std::vector<std::array<Vec3, 3>> tris;
  for (const auto& q : cube_quads()) {
    tris.push_back({v[size_t(q[0])], v[size_t(q[1])], v[size_t(q[2])]});
    tris.push_back({v[size_t(q[0])], v[size_t(q[2])], v[size_t(q[3])]});
  }
  return tris;
}

std::string cube_stl_ascii() {
  std::string s = "solid cube\n";
  for (const auto& t : cube_triangles()) {
    const Vec3 n = glm::normalize(glm::cross(t[1] - t[0], t[2] - t[0]));
    s += "  facet normal " + vertex_line(n) + "\n    outer loop\n";
    for (const Vec3& p : t) s += "      vertex " + vertex_line(p) + "\n";
    s += "    endloop\n  endfacet\n";
  }
  return s + "endsolid cube\n";
}

std::string cube_stl_binary() {
  std::string s = "solid: a binary STL may start like an ASCII one";
  s.resize(80, ' ');
  const auto tris = cube_triangles();
  put(s, uint32_t(tris.size()));
  for (const auto& t : tris) {
    const Vec3 n = glm::normalize(glm::cross(t[1] - t[0], t[2] - t[0]));
    for (double c : {n.x, n.y, n.z}) put(s, float(c));
    for (const Vec3& p : t)
      for (double c : {p.x, p.y, p.z}) put(s, float(c));
    put(s, uint16_t(0));
  }
  return s;
}

std::string cube_off() {
  std::string s = "OFF\n# cube\n8 6 12\n";
  for (const Vec3& p : corners()) s += vertex_line(p) + "\n";
  for (const auto& q : cube_quads())
    s += "4 " + std::to_string(q[0]) + " " + std::to_string(q[1]) + " " + std::to_string(q[2]) + " " +
         std::to_string(q[3]) + " 255 0 0\n";  // with a face colour
  return s;
}

std::string ply_header(const char* format, const char* scalar) {
  return std::string("ply\nformat ") + format + " 1.0\ncomment cube\nelement vertex 8\nproperty " + scalar +
         " x\nproperty " + scalar + " y\nproperty " + scalar +
         " z\nelement face 6\nproperty list uchar int vertex_indices\nend_header\n";
}

std::string cube_ply_ascii() {
  std::string s = ply_header("ascii", "float");
  for (const Vec3& p : corners()) s += vertex_line(p) + "\n";
  for (const auto& q : cube_quads())
    s += "4 " + std::to_string(q[0]) + " " + std::to_string(q[1]) + " " + std::to_string(q[2]) + " " +
         std::to_string(q[3]) + "\n";
  return s;
}

std::string cube_ply_binary() {
  std::string s = ply_header("binary_little_endian", "double");
  for (const Vec3& p : corners())
    for (double c : {p.x, p.y, p.z}) put(s, c);
  for (const auto& q : cube_quads()) {
    put(s, uint8_t(4));
    for (int32_t id : q) put(s, id);
  }
  return s;
}

struct Format {
  const char* name;
  const char* file;  // some in upper case: extensions are case-insensitive
  std::string (*write)();
};

class ReadSurface : public ::testing::TestWithParam<Format> {};

TEST_P(ReadSurface, ReadsTheCubeWeldedAndTetGenFillsItsVolume) {
  const TempDir dir;
  const std::string path = dir.file(GetParam().file);
  write_file(path, GetParam().write());
  const SurfaceMesh s = read_surface(path);
  EXPECT_EQ(s.vertices.size(), 8u);
  EXPECT_EQ(s.triangles.size(), 12u);
  EXPECT_EQ(test::count_open_edges(s.triangles), 0);
  const Aabb box = compute_aabb(s.vertices);
  EXPECT_EQ(box.lo, kLo);
  EXPECT_EQ(box.hi, kHi);
  const TetMesh m = tetrahedralize(s, {});
  EXPECT_EQ(test::count_nonpositive_tets(m), 0);
  EXPECT_NEAR(test::compute_mesh_volume(m), kCubeVolume, 1e-14);
}

INSTANTIATE_TEST_SUITE_P(Formats, ReadSurface,
                         ::testing::Values(Format{"obj", "cube.obj", cube_obj},
                                           Format{"stl_ascii", "cube.stl", cube_stl_ascii},
                                           Format{"stl_binary", "CUBE.STL", cube_stl_binary},
                                           Format{"off", "cube.Off", cube_off},
                                           Format{"ply_ascii", "cube.ply", cube_ply_ascii},
                                           Format{"ply_binary", "cube_binary.PLY", cube_ply_binary}),
                         [](const auto& p) { return std::string(p.param.name); });

TEST(ReadSurfaceErrors, MissingFileAndUnknownExtension) {
  const TempDir dir;
  expect_mesh_error([&] { read_surface(dir.file("missing.obj")); }, {"missing.obj", "not found"});
  write_file(dir.file("cube.xyz"), cube_obj());
  expect_mesh_error([&] { read_surface(dir.file("cube.xyz")); }, {"cube.xyz", "unknown", "'.xyz'"});
}

TEST(ReadSurfaceErrors, NoTriangles) {
  const TempDir dir;
  write_file(dir.file("points.off"), "OFF\n3 0 0\n0 0 0\n1 0 0\n0 1 0\n");
  expect_mesh_error([&] { read_surface(dir.file("points.off")); }, {"points.off", "no triangles"});
  write_file(dir.file("lines.obj"), "# only lines here\nv 0 0 0\nv 1 0 0\nv 0 1 0\nl 1 2\nl 2 3\n");
  expect_mesh_error([&] { read_surface(dir.file("lines.obj")); }, {"lines.obj", "no triangles"});
}

TEST(ReadSurfaceErrors, NonFiniteCoordinate) {
  const TempDir dir;
  write_file(dir.file("nan.off"), "OFF\n4 1 0\n0 0 0\n1 0 0\n0 nan 0\n0 0 1\n3 0 1 2\n");
  expect_mesh_error([&] { read_surface(dir.file("nan.off")); }, {"nan.off:5", "vertex 2", "non-finite"});
  write_file(dir.file("nan.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 nan\nf 1 2 3\nf 1 2 4\n");
  expect_mesh_error([&] { read_surface(dir.file("nan.obj")); }, {"nan.obj", "non-finite"});
}

TEST(ReadSurfaceErrors, IndexOutOfRange) {
  const TempDir dir;
  write_file(dir.file("bad.off"), "OFF\n4 2 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 1 2\n3 0 1 4\n");
  expect_mesh_error([&] { read_surface(dir.file("bad.off")); }, {"bad.off:8", "vertex 4", "outside 0..3"});
  write_file(dir.file("bad.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 9\n");
  expect_mesh_error([&] { read_surface(dir.file("bad.obj")); }, {"bad.obj", "out of range"});
  std::string ply = cube_ply_ascii();
  ply.replace(ply.rfind("4 1 3 7 5"), 9, "4 1 3 7 8");
  write_file(dir.file("bad.ply"), ply);
  expect_mesh_error([&] { read_surface(dir.file("bad.ply")); }, {"bad.ply", "out of range"});
}

// A header that declares more than its body can hold is refused before
// Assimp reserves for it (a 263-byte file declaring 10^8 vertices took
// 2.8 GB and a minute), naming the count and the bound.
TEST(ReadSurfaceErrors, PlyCountsTheBodyCannotHoldAreRefusedBeforeReading) {
  const TempDir dir;
  std::string ascii = cube_ply_ascii();
  ascii.replace(ascii.find("element vertex 8"), 16, "element vertex 100000000");
  write_file(dir.file("huge.ply"), ascii);
  expect_mesh_error([&] { read_surface(dir.file("huge.ply")); },
                    {"huge.ply:4", "element 'vertex' declares 100000000 items", "hold at most", "ascii"});
  std::string binary = cube_ply_binary();
  binary.replace(binary.find("element face 6"), 14, "element face 100000000");
  write_file(dir.file("faces.ply"), binary);
  expect_mesh_error([&] { read_surface(dir.file("faces.ply")); },
                    {"faces.ply:8", "element 'face' declares 100000000 items", "(1 bytes each at least"});
  // Vertices of 3 doubles: the body's 294 bytes (8 x 24 of vertices, 6 x 17
  // of faces) would hold 12 of them.
  binary = cube_ply_binary();
  binary.replace(binary.find("element vertex 8"), 16, "element vertex 13");
  write_file(dir.file("more.ply"), binary);
  expect_mesh_error([&] { read_surface(dir.file("more.ply")); },
                    {"more.ply:4", "declares 13 items", "hold at most 12 (24 bytes each at least"});
  write_file(dir.file("no_end.ply"), "ply\nformat ascii 1.0\nelement vertex 3\n");
  expect_mesh_error([&] { read_surface(dir.file("no_end.ply")); }, {"no_end.ply", "no PLY end_header"});
  write_file(dir.file("count.ply"), "ply\nformat ascii 1.0\nelement vertex -3\nend_header\n");
  expect_mesh_error([&] { read_surface(dir.file("count.ply")); }, {"count.ply:3", "no valid count ('-3')"});
}

TEST(WriteSurfaceObj, RoundTripsThroughReadSurface) {
  const TempDir dir;
  SurfaceMesh s = test::make_cube_surface();
  write_surface_obj(s, dir.file("out.obj"));
  const SurfaceMesh r = read_surface(dir.file("out.obj"));
  EXPECT_EQ(r.vertices.size(), 8u);
  EXPECT_EQ(r.triangles.size(), 12u);
  EXPECT_EQ(test::count_open_edges(r.triangles), 0);
  EXPECT_NEAR(test::compute_mesh_volume(tetrahedralize(r, {})), 1.0, 1e-14);
}

TEST(TetgenFiles, RoundTripByBaseNodeAndElePath) {
  const TempDir dir;
  TetMesh m = make_box(Vec3(0.1, 0.2, 0.3), Vec3(1.0 / 3.0, 0.7, 0.9), {2, 3, 1});
  for (int32_t e = 0; e < m.n_tets(); ++e) m.region.push_back(e % 3 - 1);
  write_tetgen(m, dir.file("box"));
  for (const char* path : {"box", "box.node", "box.ele"}) {
    SCOPED_TRACE(path);
    const TetMesh r = read_tetgen(dir.file(path));
    EXPECT_EQ(r.X, m.X);  // exact: 17 digits
    EXPECT_EQ(r.tets, m.tets);
    EXPECT_EQ(r.region, m.region);
  }
}

TEST(TetgenFiles, ReadsOneBasedNumberingAttributesMarkersAndRegions) {
  const TempDir dir;
  write_file(dir.file("one.node"),
             "# 1-based, one attribute, boundary markers\n"
             "5 3 1 1\n"
             "1  0 0 0  7.5 1\n"
             "2  1 0 0  7.5 1\n"
             "\n"
             "3  0 1 0  7.5 1   # a comment\n"
             "4  0 0 1  7.5 1\n"
             "5  1 1 1  7.5 0\n");
  write_file(dir.file("one.ele"),
             "2 4 1\n"
             "1  1 2 3 4  3\n"
             "2  3 2 4 5  -2   # negative volume as written\n");
  const TetMesh m = read_tetgen(dir.file("one"));
  ASSERT_EQ(m.n_nodes(), 5);
  EXPECT_EQ(m.X[4], Vec3(1.0, 1.0, 1.0));
  ASSERT_EQ(m.n_tets(), 2);
  EXPECT_EQ(m.tets[0], (Tet{0, 1, 2, 3}));
  Tet second = m.tets[1];
  std::sort(second.begin(), second.end());
  EXPECT_EQ(second, (Tet{1, 2, 3, 4}));
  EXPECT_EQ(test::count_nonpositive_tets(m), 0);  // reoriented
  EXPECT_EQ(m.region, (std::vector<int32_t>{3, -2}));
  EXPECT_EQ(check_mesh_structure(m), "");
}

// Ten nodes a tet (TetGen -o2): a quadratic mesh, written and read back; the
// edge nodes found by where they sit, whatever order a writer lists them in;
// one off its edge's midpoint (a curved tet) refused, naming the tet and edge.
TEST(TetgenFiles, TenNodeTetsReadAsAQuadraticMeshInAnyEdgeOrder) {
  const TempDir dir;
  TetMesh m = make_quadratic_mesh(make_box(Vec3(0.0), Vec3(0.3, 0.2, 0.1), {3, 2, 1}));
  write_tetgen(m, dir.file("q"));
  const TetMesh r = read_tetgen(dir.file("q"));
  EXPECT_EQ(r.X, m.X);
  EXPECT_EQ(r.tets, m.tets);
  EXPECT_EQ(r.edges, m.edges);
  EXPECT_EQ(check_mesh_structure(r), "");
  // 1-based, the edge nodes listed in another order (TetGen's own differs from VTK's).
  auto node_file = [&] {
    std::ostringstream out;
    out << m.n_nodes() << " 3 0 0\n";
    for (int32_t i = 0; i < m.n_nodes(); ++i)
      out << i + 1 << ' ' << m.X[size_t(i)].x << ' ' << m.X[size_t(i)].y << ' ' << m.X[size_t(i)].z << '\n';
    return out.str();
  };
  std::ostringstream ele;
  ele << m.n_tets() << " 10 0\n";
  constexpr int kShuffled[6] = {3, 0, 5, 1, 4, 2};
  for (int32_t e = 0; e < m.n_tets(); ++e) {
    ele << e + 1;
    for (int k = 0; k < 4; ++k) ele << ' ' << m.tets[size_t(e)][size_t(k)] + 1;
    for (int k : kShuffled) ele << ' ' << m.edges[size_t(e)][size_t(k)] + 1;
    ele << '\n';
  }
  write_file(dir.file("t.node"), node_file());
  write_file(dir.file("t.ele"), ele.str());
  EXPECT_EQ(read_tetgen(dir.file("t")).edges, m.edges);
  // An edge node moved off its midpoint.
  m.X[size_t(m.edges[0][3])] += Vec3(0.0, 0.004, 0.0);
  write_file(dir.file("c.node"), node_file());
  write_file(dir.file("c.ele"), ele.str());
  expect_mesh_error([&] { read_tetgen(dir.file("c")); },
                    {"c.ele:2", "tet 1: no edge node at the midpoint of its edge", "curved quadratic tets"});
  write_file(dir.file("n.node"), node_file());
  write_file(dir.file("n.ele"), "1 8 0\n0 0 1 2 3 4 5 6 7\n");
  expect_mesh_error([&] { read_tetgen(dir.file("n")); }, {"nodes per tet is 8"});
}

TEST(TetgenFiles, RefusesAnOutOfRangeNodeNamingTheLine) {
  const TempDir dir;
  write_file(dir.file("bad.node"), "4 3 0 0\n0 0 0 0\n1 1 0 0\n2 0 1 0\n3 0 0 1\n");
  write_file(dir.file("bad.ele"), "# one tet\n1 4 0\n0 0 1 2 4\n");
  expect_mesh_error([&] { read_tetgen(dir.file("bad.ele")); }, {"bad.ele:3", "node 4", "0..3"});
}

TEST(TetgenFiles, RefusesMissingAndMalformedFiles) {
  const TempDir dir;
  write_file(dir.file("lone.node"), "4 3 0 0\n0 0 0 0\n1 1 0 0\n2 0 1 0\n3 0 0 1\n");
  expect_mesh_error([&] { read_tetgen(dir.file("lone")); }, {"lone.ele", "not found"});
  write_file(dir.file("short.node"), "4 3 0 0\n0 0 0 0\n1 1 0 0\n2 0 x 0\n3 0 0 1\n");
  expect_mesh_error([&] { read_tetgen(dir.file("short")); }, {"short.node:4", "'x'"});
  write_file(dir.file("gap.node"), "4 3 0 0\n0 0 0 0\n1 1 0 0\n3 0 1 0\n4 0 0 1\n");
  expect_mesh_error([&] { read_tetgen(dir.file("gap")); }, {"gap.node:4", "out of sequence"});
}

}  // namespace
}  // namespace tactile
