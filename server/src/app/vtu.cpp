#include "app/vtu.hpp"

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <stdexcept>

#include <glm/geometric.hpp>

namespace tactile {

std::string encode_base64(const void* data, size_t n_bytes) {
  static constexpr char kAlphabet[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  const auto* p = static_cast<const uint8_t*>(data);
  std::string out;
  out.reserve((n_bytes + 2) / 3 * 4);
  size_t i = 0;
  for (; i + 3 <= n_bytes; i += 3) {
    const uint32_t w = uint32_t(p[i]) << 16 | uint32_t(p[i + 1]) << 8 | p[i + 2];
    out += kAlphabet[w >> 18];
    out += kAlphabet[(w >> 12) & 63];
    out += kAlphabet[(w >> 6) & 63];
    out += kAlphabet[w & 63];
  }
  if (i < n_bytes) {
    const bool two = i + 1 < n_bytes;
    const uint32_t w = uint32_t(p[i]) << 16 | (two ? uint32_t(p[i + 1]) << 8 : 0u);
    out += kAlphabet[w >> 18];
    out += kAlphabet[(w >> 12) & 63];
    out += two ? kAlphabet[(w >> 6) & 63] : '=';
    out += '=';
  }
  return out;
}

namespace {

// An inline binary DataArray: base64 of [UInt64 byte count][values].
template <class T>
void write_array(std::ofstream& out, const char* type, const char* name, int components, const std::vector<T>& values,
                 int tuples = 0) {
  std::vector<uint8_t> bytes(sizeof(uint64_t) + values.size() * sizeof(T));
  const uint64_t n = values.size() * sizeof(T);
  std::memcpy(bytes.data(), &n, sizeof n);
  if (n) std::memcpy(bytes.data() + sizeof n, values.data(), n);
  out << "        <DataArray type=\"" << type << "\"";
  if (name) out << " Name=\"" << name << "\"";
  if (components > 1) out << " NumberOfComponents=\"" << components << "\"";
  if (tuples > 0) out << " NumberOfTuples=\"" << tuples << "\"";  // field data gives its count
  out << " format=\"binary\">\n          " << encode_base64(bytes.data(), bytes.size()) << "\n        </DataArray>\n";
}

std::ofstream open(const std::string& path) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) throw std::runtime_error(path + ": cannot open for writing");
  return out;
}

void close(std::ofstream& out, const std::string& path) {
  out.close();
  if (!out) throw std::runtime_error(path + ": write failed");
}

// The file's opening, up to the grid's FieldData and Piece; write_piece ends
// the piece with its Points and Cells (one VTK cell type) and the file.
void begin_grid(std::ofstream& out) {
  out << "<?xml version=\"1.0\"?>\n"
         "<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\">\n"
         "  <UnstructuredGrid>\n";
}

void write_piece(std::ofstream& out, const std::vector<double>& points, const std::vector<int32_t>& connectivity,
                 int corners, uint8_t type) {
  const size_t nc = connectivity.size() / size_t(corners);
  std::vector<int32_t> offsets(nc);
  for (size_t e = 0; e < nc; ++e) offsets[e] = int32_t(size_t(corners) * (e + 1));
  const std::vector<uint8_t> types(nc, type);
  out << "      <Points>\n";
  write_array(out, "Float64", "Points", 3, points);
  out << "      </Points>\n"
         "      <Cells>\n";
  write_array(out, "Int32", "connectivity", 1, connectivity);
  write_array(out, "Int32", "offsets", 1, offsets);
  write_array(out, "UInt8", "types", 1, types);
  out << "      </Cells>\n"
         "    </Piece>\n"
         "  </UnstructuredGrid>\n"
         "</VTKFile>\n";
}

}  // namespace

void write_vtu(const std::string& path, const VtuFrame& f) {
  const TetMesh& mesh = *f.mesh;
  // The nodes and tets written: the whole mesh, or one body's ranges.
  const auto n0 = size_t(f.body ? f.body->node_begin : 0), n1 = size_t(f.body ? f.body->node_end : mesh.n_nodes());
  const auto t0 = size_t(f.body ? f.body->tet_begin : 0), t1 = size_t(f.body ? f.body->tet_end : mesh.n_tets());
  const size_t nn = n1 - n0, nt = t1 - t0;
  std::vector<double> points(3 * nn);
  for (size_t i = 0; i < nn; ++i)
    for (size_t d = 0; d < 3; ++d) points[3 * i + d] = mesh.X[n0 + i][int(d)];
  // A quadratic mesh as VTK_QUADRATIC_TETRA (24), whose node order is ours
  // (core/mesh.hpp): ParaView draws its curved faces as they are.
  const auto per = size_t(mesh.nodes_per_tet());
  std::vector<int32_t> connectivity(per * nt), material(nt);
  for (size_t e = 0; e < nt; ++e) {
    for (size_t k = 0; k < per; ++k) connectivity[per * e + k] = mesh.node(t0 + e, int(k)) - int32_t(n0);
    material[e] = mesh.region_of(int32_t(t0 + e));
  }
  // An array's entries of the written nodes or tets (`width` values each).
  const auto nodes = [&](const auto& a, size_t width) {
    return std::vector<typename std::decay_t<decltype(a)>::value_type>(a.begin() + ptrdiff_t(width * n0),
                                                                       a.begin() + ptrdiff_t(width * n1));
  };
  const auto tets = [&](const std::vector<double>& a, size_t width) {
    return std::vector<double>(a.begin() + ptrdiff_t(width * t0), a.begin() + ptrdiff_t(width * t1));
  };

  std::ofstream out = open(path);
  begin_grid(out);
  out << "    <Piece NumberOfPoints=\"" << nn << "\" NumberOfCells=\"" << nt << "\">\n";
  out << "      <PointData" << (f.u ? " Vectors=\"displacement\"" : "") << ">\n";
  if (f.u) write_array(out, "Float64", "displacement", 3, nodes(*f.u, 3));
  if (f.v) write_array(out, "Float64", "velocity", 3, nodes(*f.v, 3));
  if (f.fixed) write_array(out, "UInt8", "fixed", 1, nodes(*f.fixed, 1));
  if (f.contact_force) write_array(out, "Float64", "contact_force", 3, nodes(*f.contact_force, 3));
  out << "      </PointData>\n";
  const ElementFields* fields = f.fields;
  const bool stress = fields && !fields->cauchy_stress.empty();
  out << "      <CellData Scalars=\"" << (fields && !fields->von_mises.empty() ? "von_mises" : "strain_energy_density")
      << "\"" << (stress ? " Tensors=\"cauchy_stress\"" : "") << ">\n";
  if (f.energy_density) write_array(out, "Float64", "strain_energy_density", 1, tets(*f.energy_density, 1));
  if (stress) write_array(out, "Float64", "cauchy_stress", 9, tets(fields->cauchy_stress, 9));
  if (fields && !fields->green_strain.empty())
    write_array(out, "Float64", "green_strain", 9, tets(fields->green_strain, 9));
  if (fields && !fields->von_mises.empty()) write_array(out, "Float64", "von_mises", 1, tets(fields->von_mises, 1));
  if (fields && !fields->principal_stretches.empty())
    write_array(out, "Float64", "principal_stretches", 3, tets(fields->principal_stretches, 3));
  write_array(out, "Int32", "material", 1, material);
  out << "      </CellData>\n";
  write_piece(out, points, connectivity, int(per), mesh.quadratic() ? 24 : 10);  // VTK_QUADRATIC_TETRA, VTK_TETRA
  close(out, path);
}

void write_vtu(const std::string& path, const VtuSurface& f) {
  const EmbeddedSurface& e = *f.surface;
  const std::vector<double>& u = *f.u;
  // The vertices and triangles written: all, or one body's ranges (its own numbering).
  const auto v0 = size_t(f.body ? f.body->fine_vertex_begin : 0);
  const auto v1 = size_t(f.body ? f.body->fine_vertex_end : e.n_vertices());
  const auto r0 = size_t(f.body ? f.body->fine_triangle_begin : 0);
  const auto r1 = size_t(f.body ? f.body->fine_triangle_end : e.rest.triangles.size());
  const size_t nv = v1 - v0;
  std::vector<double> points(3 * nv), displacement(3 * nv, 0.0), outside(nv);
  std::vector<int32_t> tet(nv);
  const int32_t first_tet = f.body ? f.body->tet_begin : 0;
  for (size_t i = 0; i < nv; ++i) {
    for (size_t d = 0; d < 3; ++d) {
      points[3 * i + d] = e.rest.vertices[v0 + i][int(d)];
      for (size_t k = 0; k < 4; ++k)
        displacement[3 * i + d] += e.weights[v0 + i][k] * u[3 * size_t(e.nodes[v0 + i][k]) + d];
    }
    tet[i] = e.tet[v0 + i] - first_tet;
    outside[i] = e.outside[v0 + i];
  }
  std::vector<int32_t> connectivity;
  connectivity.reserve(3 * (r1 - r0));
  for (size_t t = r0; t < r1; ++t)
    for (int32_t v : e.rest.triangles[t]) connectivity.push_back(v - int32_t(v0));
  std::ofstream out = open(path);
  begin_grid(out);
  out << "    <Piece NumberOfPoints=\"" << nv << "\" NumberOfCells=\"" << connectivity.size() / 3 << "\">\n"
      << "      <PointData Vectors=\"displacement\">\n";
  write_array(out, "Float64", "displacement", 3, displacement);
  write_array(out, "Int32", "tet", 1, tet);
  write_array(out, "Float64", "outside", 1, outside);
  out << "      </PointData>\n";
  write_piece(out, points, connectivity, 3, 5);  // VTK_TRIANGLE
  close(out, path);
}

ProxySurface make_proxy_surface(const ProxyGeometry& g, const Pose& pose, double plane_half_size, int n) {
  ProxySurface s;
  auto put = [&](const Vec3& local) {
    const Vec3 x = pose.to_world(local);
    s.points.insert(s.points.end(), {x.x, x.y, x.z});
  };
  if (g.shape == ProxyShape::Plane) {  // the half-space y <= 0: its face, a square in the proxy's xz plane
    const double h = plane_half_size;
    for (const Vec3& c : {Vec3(-h, 0, -h), Vec3(h, 0, -h), Vec3(h, 0, h), Vec3(-h, 0, h)}) put(c);
    s.triangles = {0, 2, 1, 0, 3, 2};  // facing +y, out of the half-space
    return s;
  }
  n = std::max(2, n + (n & 1));
  // The core's support point along d, with sign(0) = 0 so that directions on
  // the cube's middle lines land on the middles of the core's faces and edges.
  auto sign = [](double x) { return x > 0 ? 1.0 : x < 0 ? -1.0 : 0.0; };
  auto support = [&](const Vec3& d) {
    switch (g.shape) {
      case ProxyShape::Capsule: return Vec3(sign(d.x) * g.half_length, 0.0, 0.0);
      case ProxyShape::Box: return Vec3(sign(d.x), sign(d.y), sign(d.z)) * g.half_extents;
      default: return Vec3(0.0);
    }
  };
  for (int face = 0; face < 6; ++face) {
    const int axis = face / 2;
    const double side = face % 2 ? -1.0 : 1.0;
    const int a1 = (axis + 1) % 3, a2 = (axis + 2) % 3;
    const auto base = int32_t(s.points.size() / 3);
    for (int i = 0; i <= n; ++i)
      for (int j = 0; j <= n; ++j) {
        Vec3 q(0.0);
        q[axis] = side;
        q[a1] = -1.0 + 2.0 * i / n;
        q[a2] = -1.0 + 2.0 * j / n;
        const Vec3 d = glm::normalize(q);
        put(support(d) + g.radius * d);
      }
    for (int i = 0; i < n; ++i)
      for (int j = 0; j < n; ++j) {
        const int32_t k = base + int32_t(i * (n + 1) + j);
        const int32_t right = k + n + 1, up = k + 1, diag = k + n + 2;
        // Outward: (a1, a2, axis) is right-handed, so (i, j) counter-clockwise seen from +axis.
        if (side > 0)
          s.triangles.insert(s.triangles.end(), {k, right, diag, k, diag, up});
        else
          s.triangles.insert(s.triangles.end(), {k, diag, right, k, up, diag});
      }
  }
  return s;
}

void write_vtu(const std::string& path, const VtuProxy& p) {
  const ProxySurface& surface = *p.surface;
  const size_t np = surface.points.size() / 3, nc = surface.triangles.size() / 3;
  std::ofstream out = open(path);
  begin_grid(out);
  out << "    <FieldData>\n";
  write_array(out, "Float64", "force", 3, std::vector<double>{p.force.x, p.force.y, p.force.z}, 1);
  write_array(out, "Float64", "torque", 3, std::vector<double>{p.torque.x, p.torque.y, p.torque.z}, 1);
  write_array(out, "Int32", "contacts", 1, std::vector<int32_t>{p.contacts}, 1);
  out << "    </FieldData>\n";
  out << "    <Piece NumberOfPoints=\"" << np << "\" NumberOfCells=\"" << nc << "\">\n"
      << "      <PointData Vectors=\"displacement\">\n";
  write_array(out, "Float64", "displacement", 3, std::vector<double>(3 * np, 0.0));
  out << "      </PointData>\n";
  write_piece(out, surface.points, surface.triangles, 3, 5);  // VTK_TRIANGLE
  close(out, path);
}

void write_pvd(const std::string& path, const std::vector<PvdEntry>& entries) {
  std::ofstream out = open(path);
  out << "<?xml version=\"1.0\"?>\n"
         "<VTKFile type=\"Collection\" version=\"0.1\" byte_order=\"LittleEndian\">\n"
         "  <Collection>\n";
  char t[32];
  for (const PvdEntry& e : entries) {
    std::snprintf(t, sizeof t, "%.9g", e.t);
    out << "    <DataSet timestep=\"" << t << "\" group=\"\" part=\"" << e.part << "\"";
    if (!e.name.empty()) out << " name=\"" << e.name << "\"";
    out << " file=\"" << e.file << "\"/>\n";
  }
  out << "  </Collection>\n"
         "</VTKFile>\n";
  close(out, path);
}

}  // namespace tactile
