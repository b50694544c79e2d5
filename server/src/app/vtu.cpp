#include "app/vtu.hpp"

#include <cstdint>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <stdexcept>

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
void write_array(std::ofstream& out, const char* type, const char* name, int components, const std::vector<T>& values) {
  std::vector<uint8_t> bytes(sizeof(uint64_t) + values.size() * sizeof(T));
  const uint64_t n = values.size() * sizeof(T);
  std::memcpy(bytes.data(), &n, sizeof n);
  if (n) std::memcpy(bytes.data() + sizeof n, values.data(), n);
  out << "        <DataArray type=\"" << type << "\"";
  if (name) out << " Name=\"" << name << "\"";
  if (components > 1) out << " NumberOfComponents=\"" << components << "\"";
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

}  // namespace

void write_vtu(const std::string& path, const VtuFrame& f) {
  const TetMesh& mesh = *f.mesh;
  const auto nn = size_t(mesh.n_nodes()), nt = size_t(mesh.n_tets());
  std::vector<double> points(3 * nn);
  for (size_t i = 0; i < nn; ++i)
    for (size_t d = 0; d < 3; ++d) points[3 * i + d] = mesh.X[i][int(d)] + (f.u ? (*f.u)[3 * i + d] : 0.0);
  std::vector<int32_t> connectivity(4 * nt), offsets(nt), material(nt);
  std::vector<uint8_t> types(nt, 10);  // VTK_TETRA
  for (size_t e = 0; e < nt; ++e) {
    for (size_t k = 0; k < 4; ++k) connectivity[4 * e + k] = mesh.tets[e][k];
    offsets[e] = int32_t(4 * (e + 1));
    material[e] = mesh.region_of(int32_t(e));
  }

  std::ofstream out = open(path);
  out << "<?xml version=\"1.0\"?>\n"
         "<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\">\n"
         "  <UnstructuredGrid>\n"
      << "    <Piece NumberOfPoints=\"" << nn << "\" NumberOfCells=\"" << nt << "\">\n";
  out << "      <PointData Vectors=\"displacement\">\n";
  if (f.u) write_array(out, "Float64", "displacement", 3, *f.u);
  if (f.v) write_array(out, "Float64", "velocity", 3, *f.v);
  out << "      </PointData>\n";
  out << "      <CellData Scalars=\"strain_energy_density\">\n";
  if (f.energy_density) write_array(out, "Float64", "strain_energy_density", 1, *f.energy_density);
  write_array(out, "Int32", "material", 1, material);
  out << "      </CellData>\n";
  out << "      <Points>\n";
  write_array(out, "Float64", "Points", 3, points);
  out << "      </Points>\n";
  out << "      <Cells>\n";
  write_array(out, "Int32", "connectivity", 1, connectivity);
  write_array(out, "Int32", "offsets", 1, offsets);
  write_array(out, "UInt8", "types", 1, types);
  out << "      </Cells>\n"
         "    </Piece>\n"
         "  </UnstructuredGrid>\n"
         "</VTKFile>\n";
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
    out << "    <DataSet timestep=\"" << t << "\" group=\"\" part=\"0\" file=\"" << e.file << "\"/>\n";
  }
  out << "  </Collection>\n"
         "</VTKFile>\n";
  close(out, path);
}

}  // namespace tactile
