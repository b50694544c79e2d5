#include "mesh/mesh_io.hpp"

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <sstream>
#include <string_view>

#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <assimp/Importer.hpp>

#include <glm/geometric.hpp>

#include "mesh/mesh_error.hpp"

namespace tactile {
namespace {

namespace fs = std::filesystem;

std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return s;
}

std::string format_vec(const Vec3& p) {
  char buf[96];
  std::snprintf(buf, sizeof buf, "(%.9g, %.9g, %.9g)", p.x, p.y, p.z);
  return buf;
}

bool is_finite(const Vec3& p) { return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z); }

void require_file(const std::string& path) {
  std::error_code ec;
  if (!fs::exists(path, ec)) throw MeshError(path + ": file not found");
  if (!fs::is_regular_file(path, ec)) throw MeshError(path + ": not a regular file");
}

std::string read_text(const std::string& path) {
  require_file(path);
  std::ifstream in(path, std::ios::binary);
  if (!in) throw MeshError(path + ": cannot open for reading");
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

// --- text files: content lines, '#' comments, whitespace-separated tokens ---

struct Line {
  int number;                           // 1-based line number in the file
  std::vector<std::string_view> words;  // non-empty
};

// The non-blank lines of `text`, comments removed. Views point into `text`.
std::vector<Line> split_lines(const std::string& text) {
  std::vector<Line> lines;
  int number = 0;
  size_t begin = 0;
  while (begin < text.size()) {
    size_t end = text.find('\n', begin);
    if (end == std::string::npos) end = text.size();
    ++number;
    std::string_view line(text.data() + begin, end - begin);
    if (const size_t hash = line.find('#'); hash != std::string_view::npos) line = line.substr(0, hash);
    Line out{number, {}};
    size_t i = 0;
    while (i < line.size()) {
      while (i < line.size() && std::isspace(static_cast<unsigned char>(line[i]))) ++i;
      size_t j = i;
      while (j < line.size() && !std::isspace(static_cast<unsigned char>(line[j]))) ++j;
      if (j > i) out.words.push_back(line.substr(i, j - i));
      i = j;
    }
    if (!out.words.empty()) lines.push_back(std::move(out));
    begin = end + 1;
  }
  return lines;
}

// Parses whole words of a text file, naming file and line on error.
struct WordParser {
  const std::string& path;

  [[noreturn]] void fail(const Line& line, const std::string& what) const {
    throw MeshError(path + ":" + std::to_string(line.number) + ": " + what);
  }
  int64_t integer(const Line& line, size_t w, const char* what) const {
    if (w >= line.words.size()) fail(line, std::string("missing ") + what);
    const std::string_view s = line.words[w];
    int64_t v = 0;
    auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
    if (ec != std::errc() || end != s.data() + s.size())
      fail(line, std::string(what) + " '" + std::string(s) + "' is not an integer");
    return v;
  }
  double real(const Line& line, size_t w, const char* what) const {
    if (w >= line.words.size()) fail(line, std::string("missing ") + what);
    const std::string_view s = line.words[w];
    double v = 0;
    auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
    if (ec != std::errc() || end != s.data() + s.size())
      fail(line, std::string(what) + " '" + std::string(s) + "' is not a number");
    return v;
  }
};

// --- OFF (our own reader) ---

SurfaceMesh read_off(const std::string& path) {
  const std::string text = read_text(path);
  const std::vector<Line> lines = split_lines(text);
  const WordParser p{path};
  if (lines.empty()) throw MeshError(path + ": empty file");
  // Header keyword [ST][C][N][4][n]OFF; only 3-D ASCII is read here.
  const Line& head = lines[0];
  const std::string_view key = head.words[0];
  if (key.size() < 3 || key.substr(key.size() - 3) != "OFF") p.fail(head, "not an OFF file (no OFF header)");
  if (key.find('4') != std::string_view::npos || key.find('n') != std::string_view::npos)
    p.fail(head, "only 3-D OFF is supported, not " + std::string(key));
  size_t next = 1;
  Line counts = head;
  counts.words.erase(counts.words.begin());
  if (!counts.words.empty() && lower(std::string(counts.words[0])) == "binary")
    p.fail(head, "binary OFF is not supported");
  if (counts.words.empty()) {
    if (lines.size() < 2) throw MeshError(path + ": missing the vertex and face counts");
    counts = lines[next++];
  }
  const int64_t nv = p.integer(counts, 0, "vertex count");
  const int64_t nf = p.integer(counts, 1, "face count");
  if (nv < 0 || nf < 0 || nv > std::numeric_limits<int32_t>::max()) p.fail(counts, "invalid vertex or face count");
  if (lines.size() < next + size_t(nv) + size_t(nf))
    throw MeshError(path + ": ends early; line " + std::to_string(counts.number) + " declares " + std::to_string(nv) +
                    " vertices and " + std::to_string(nf) + " faces");

  SurfaceMesh s;
  s.vertices.reserve(size_t(nv));
  for (int64_t i = 0; i < nv; ++i) {
    const Line& line = lines[next++];
    const Vec3 x(p.real(line, 0, "x"), p.real(line, 1, "y"), p.real(line, 2, "z"));
    if (!is_finite(x)) p.fail(line, "vertex " + std::to_string(i) + " has a non-finite coordinate");
    s.vertices.push_back(x);
  }
  for (int64_t f = 0; f < nf; ++f) {
    const Line& line = lines[next++];
    const int64_t n = p.integer(line, 0, "face size");
    if (n < 3) p.fail(line, "face " + std::to_string(f) + " has " + std::to_string(n) + " vertices; need >= 3");
    std::vector<int32_t> ids;
    for (int64_t k = 0; k < n; ++k) {
      const int64_t id = p.integer(line, size_t(1 + k), "vertex id");
      if (id < 0 || id >= nv)
        p.fail(line, "face " + std::to_string(f) + " refers to vertex " + std::to_string(id) + ", outside 0.." +
                         std::to_string(nv - 1));
      ids.push_back(int32_t(id));
    }
    for (size_t k = 1; k + 1 < ids.size(); ++k) s.triangles.push_back({ids[0], ids[k], ids[k + 1]});
  }
  // Further lines (edges, per-face data) are ignored, as OFF allows.
  return s;
}

// --- PLY header: what the body must hold, before Assimp allocates for it ---

// Assimp's PLY reader reserves what the header declares: a 263-byte file that
// declares 10^8 vertices would take gigabytes before it failed. So the
// header is read here first, and each element's declared count is checked
// against the bytes after the header: every element takes at least
// `least` bytes (binary: its scalars' sizes and its lists' count fields;
// ASCII: a digit and a separator per property), so a count the body cannot
// hold is refused, naming the count and the bound.
void check_ply_counts(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw MeshError(path + ": cannot open for reading");
  constexpr size_t kMaxHeader = 64 * 1024;
  std::string line;
  size_t header_bytes = 0;
  int number = 0;
  std::string format;
  struct Element {
    std::string name;
    int64_t count = 0;
    int64_t least = 0;  // bytes one element takes at least
    int line = 0;
  };
  std::vector<Element> elements;
  const auto size_of = [&](const std::string& type) -> int64_t {
    static const std::map<std::string, int64_t> sizes = {{"char", 1},  {"uchar", 1},   {"int8", 1},   {"uint8", 1},
                                                         {"short", 2}, {"ushort", 2},  {"int16", 2},  {"uint16", 2},
                                                         {"int", 4},   {"uint", 4},    {"int32", 4},  {"uint32", 4},
                                                         {"float", 4}, {"float32", 4}, {"double", 8}, {"float64", 8}};
    const auto it = sizes.find(type);
    if (it == sizes.end())
      throw MeshError(path + ":" + std::to_string(number) + ": unknown PLY property type '" + type + "'");
    return it->second;
  };
  bool ended = false;
  while (std::getline(in, line)) {
    ++number;
    header_bytes += line.size() + 1;
    if (header_bytes > kMaxHeader) break;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    std::istringstream words(line);
    std::string key;
    words >> key;
    if (number == 1) {
      if (key != "ply") throw MeshError(path + ": not a PLY file (its first line is not 'ply')");
      continue;
    }
    if (key == "format") {
      words >> format;
    } else if (key == "element") {
      Element e;
      std::string count;
      words >> e.name >> count;
      const char* end = count.data() + count.size();
      if (std::from_chars(count.data(), end, e.count).ptr != end || count.empty() || e.count < 0)
        throw MeshError(path + ":" + std::to_string(number) + ": element '" + e.name + "' has no valid count ('" +
                        count + "')");
      e.line = number;
      elements.push_back(e);
    } else if (key == "property") {
      if (elements.empty()) throw MeshError(path + ":" + std::to_string(number) + ": a property before any element");
      std::string type;
      words >> type;
      const bool ascii = format == "ascii";
      if (type == "list") {
        std::string count_type, item_type;
        words >> count_type >> item_type;
        elements.back().least += ascii ? 2 : size_of(count_type);
        (void)size_of(item_type);
      } else {
        elements.back().least += ascii ? 2 : size_of(type);
      }
    } else if (key == "end_header") {
      ended = true;
      break;
    }
  }
  if (!ended) throw MeshError(path + ": no PLY end_header in its first " + std::to_string(kMaxHeader / 1024) + " KiB");
  if (format != "ascii" && format != "binary_little_endian" && format != "binary_big_endian")
    throw MeshError(path + ": PLY format '" + format + "' is not ascii, binary_little_endian or binary_big_endian");
  std::error_code ec;
  const auto file_bytes = int64_t(fs::file_size(path, ec));
  const int64_t body = ec ? 0 : std::max<int64_t>(0, file_bytes - int64_t(header_bytes));
  int64_t used = 0;  // by the elements before, at least
  for (const Element& e : elements) {
    const int64_t least = std::max<int64_t>(e.least, 1);  // an element of no properties still counts
    const int64_t room = (body - used) / least;
    if (e.count > room || e.count > std::numeric_limits<int32_t>::max())
      throw MeshError(path + ":" + std::to_string(e.line) + ": element '" + e.name + "' declares " +
                      std::to_string(e.count) + " items, but the " + std::to_string(body - used) +
                      " bytes of the file left for it hold at most " +
                      std::to_string(std::min<int64_t>(room, std::numeric_limits<int32_t>::max())) + " (" +
                      std::to_string(least) + " bytes each at least, " + format + ")");
    used += e.count * least;
  }
}

// --- OBJ, STL, PLY through Assimp ---

SurfaceMesh read_with_assimp(const std::string& path, const std::string& format) {
  require_file(path);
  Assimp::Importer importer;
  // Drop everything but positions, so JoinIdenticalVertices welds by position
  // alone (STL gives every corner its face's normal).
  importer.SetPropertyInteger(AI_CONFIG_PP_RVC_FLAGS, aiComponent_NORMALS | aiComponent_TANGENTS_AND_BITANGENTS |
                                                          aiComponent_COLORS | aiComponent_TEXCOORDS |
                                                          aiComponent_BONEWEIGHTS | aiComponent_ANIMATIONS |
                                                          aiComponent_TEXTURES | aiComponent_LIGHTS |
                                                          aiComponent_CAMERAS | aiComponent_MATERIALS);
  const unsigned flags = aiProcess_RemoveComponent | aiProcess_JoinIdenticalVertices | aiProcess_Triangulate |
                         aiProcess_PreTransformVertices | aiProcess_ValidateDataStructure;
  const aiScene* scene = importer.ReadFile(path, flags);
  if (scene == nullptr) throw MeshError(path + ": cannot read " + format + ": " + importer.GetErrorString());

  // Merge the file's meshes, welding equal positions across them.
  SurfaceMesh s;
  std::map<std::array<double, 3>, int32_t> id_at;
  for (unsigned m = 0; m < scene->mNumMeshes; ++m) {
    const aiMesh* mesh = scene->mMeshes[m];
    std::vector<int32_t> id(mesh->mNumVertices);
    for (unsigned v = 0; v < mesh->mNumVertices; ++v) {
      const aiVector3D& a = mesh->mVertices[v];
      const Vec3 x(a.x, a.y, a.z);
      if (!is_finite(x)) throw MeshError(path + ": a vertex has a non-finite coordinate " + format_vec(x));
      auto [it, inserted] = id_at.try_emplace({x.x, x.y, x.z}, int32_t(s.vertices.size()));
      if (inserted) s.vertices.push_back(x);
      id[v] = it->second;
    }
    for (unsigned f = 0; f < mesh->mNumFaces; ++f) {
      const aiFace& face = mesh->mFaces[f];
      if (face.mNumIndices != 3) continue;  // points and lines
      Tri t{};
      for (unsigned k = 0; k < 3; ++k) {
        if (face.mIndices[k] >= mesh->mNumVertices)
          throw MeshError(path + ": a face refers to vertex " + std::to_string(face.mIndices[k]) + ", outside 0.." +
                          std::to_string(mesh->mNumVertices) + " (index out of range)");
        t[k] = id[face.mIndices[k]];
      }
      s.triangles.push_back(t);
    }
  }
  return s;
}

// --- TetGen .node / .ele ---

struct NodeFile {
  std::vector<Vec3> X;
  int64_t first = 0;  // number of the first node: 0 or 1
};

NodeFile read_node_file(const std::string& path) {
  const std::string text = read_text(path);
  const std::vector<Line> lines = split_lines(text);
  const WordParser p{path};
  if (lines.empty()) throw MeshError(path + ": empty file");
  const Line& head = lines[0];
  const int64_t n = p.integer(head, 0, "node count");
  const int64_t dim = head.words.size() > 1 ? p.integer(head, 1, "dimension") : 3;
  const int64_t n_attr = head.words.size() > 2 ? p.integer(head, 2, "attribute count") : 0;
  const int64_t n_marker = head.words.size() > 3 ? p.integer(head, 3, "boundary marker count") : 0;
  if (n < 4 || n > std::numeric_limits<int32_t>::max())
    p.fail(head, "node count " + std::to_string(n) + " is not >= 4");
  if (dim != 3) p.fail(head, "dimension is " + std::to_string(dim) + "; only 3 is supported");
  if (n_attr < 0 || n_marker < 0 || n_marker > 1) p.fail(head, "invalid attribute or boundary marker count");
  if (lines.size() < size_t(n) + 1)
    throw MeshError(path + ": ends after " + std::to_string(lines.size() - 1) + " of the " + std::to_string(n) +
                    " nodes declared on line " + std::to_string(head.number));
  if (lines.size() > size_t(n) + 1)
    p.fail(lines[size_t(n) + 1], "more lines than the " + std::to_string(n) + " nodes declared");

  NodeFile out;
  out.X.reserve(size_t(n));
  for (int64_t i = 0; i < n; ++i) {
    const Line& line = lines[size_t(i) + 1];
    const int64_t id = p.integer(line, 0, "node id");
    if (i == 0) {
      if (id != 0 && id != 1)
        p.fail(line, "first node id is " + std::to_string(id) + "; numbering must start at 0 or 1");
      out.first = id;
    } else if (id != out.first + i) {
      p.fail(line,
             "node id " + std::to_string(id) + " out of sequence (expected " + std::to_string(out.first + i) + ")");
    }
    if (line.words.size() != size_t(4 + n_attr + n_marker))
      p.fail(line, "expected " + std::to_string(4 + n_attr + n_marker) + " fields (id, x, y, z, " +
                       std::to_string(n_attr) + " attributes, " + std::to_string(n_marker) + " markers), found " +
                       std::to_string(line.words.size()));
    const Vec3 x(p.real(line, 1, "x"), p.real(line, 2, "y"), p.real(line, 3, "z"));
    if (!is_finite(x)) p.fail(line, "node " + std::to_string(id) + " has a non-finite coordinate");
    out.X.push_back(x);
  }
  return out;
}

void read_ele_file(const std::string& path, const NodeFile& nodes, const std::string& node_path, TetMesh& mesh) {
  const std::string text = read_text(path);
  const std::vector<Line> lines = split_lines(text);
  const WordParser p{path};
  if (lines.empty()) throw MeshError(path + ": empty file");
  const Line& head = lines[0];
  const int64_t n = p.integer(head, 0, "tet count");
  const int64_t corners = head.words.size() > 1 ? p.integer(head, 1, "nodes per tet") : 4;
  const int64_t n_attr = head.words.size() > 2 ? p.integer(head, 2, "attribute count") : 0;
  if (n < 1 || n > std::numeric_limits<int32_t>::max()) p.fail(head, "tet count " + std::to_string(n) + " is not >= 1");
  if (corners != 4 && corners != 10)
    p.fail(head, "nodes per tet is " + std::to_string(corners) + "; must be 4, or 10 (quadratic, TetGen -o2)");
  if (n_attr < 0) p.fail(head, "invalid attribute count");
  if (lines.size() < size_t(n) + 1)
    throw MeshError(path + ": ends after " + std::to_string(lines.size() - 1) + " of the " + std::to_string(n) +
                    " tets declared on line " + std::to_string(head.number));
  if (lines.size() > size_t(n) + 1)
    p.fail(lines[size_t(n) + 1], "more lines than the " + std::to_string(n) + " tets declared");

  const auto nn = int64_t(nodes.X.size());
  mesh.tets.reserve(size_t(n));
  if (n_attr > 0) mesh.region.reserve(size_t(n));
  for (int64_t e = 0; e < n; ++e) {
    const Line& line = lines[size_t(e) + 1];
    const int64_t id = p.integer(line, 0, "tet id");
    const auto fields = size_t(1 + corners + n_attr);
    if (line.words.size() != fields)
      p.fail(line, "expected " + std::to_string(fields) + " fields (id, " + std::to_string(corners) + " nodes, " +
                       std::to_string(n_attr) + " attributes), found " + std::to_string(line.words.size()));
    std::array<int32_t, 10> t{};
    for (size_t k = 0; k < size_t(corners); ++k) {
      const int64_t node = p.integer(line, 1 + k, "node id");
      if (node < nodes.first || node >= nodes.first + nn)
        p.fail(line, "tet " + std::to_string(id) + " refers to node " + std::to_string(node) + ", but " + node_path +
                         " has nodes " + std::to_string(nodes.first) + ".." + std::to_string(nodes.first + nn - 1));
      t[k] = int32_t(node - nodes.first);
    }
    if (compute_tet_volume(nodes.X[size_t(t[0])], nodes.X[size_t(t[1])], nodes.X[size_t(t[2])], nodes.X[size_t(t[3])]) <
        0.0)
      std::swap(t[1], t[2]);
    mesh.tets.push_back({t[0], t[1], t[2], t[3]});
    if (corners == 10) {
      // The six edge nodes, each put on the edge whose midpoint it sits at (whatever order the writer
      // used): a quadratic tet here is straight, so one off its midpoint is refused, naming it.
      TetEdges edges{};
      std::array<bool, 6> used{};
      for (int k = 0; k < 6; ++k) {
        const Vec3 a = nodes.X[size_t(t[size_t(kTetEdges[k][0])])], b = nodes.X[size_t(t[size_t(kTetEdges[k][1])])];
        int best = -1;
        double best_d = std::numeric_limits<double>::infinity();
        for (int j = 0; j < 6; ++j) {
          const double d = glm::length(nodes.X[size_t(t[size_t(4 + j)])] - 0.5 * (a + b));
          if (!used[size_t(j)] && d < best_d) {
            best = j;
            best_d = d;
          }
        }
        if (!(best_d <= 1e-6 * glm::length(b - a)))
          p.fail(line, "tet " + std::to_string(id) + ": no edge node at the midpoint of its edge " +
                           std::to_string(t[size_t(kTetEdges[k][0])] + nodes.first) + "-" +
                           std::to_string(t[size_t(kTetEdges[k][1])] + nodes.first) + " (nearest " +
                           std::to_string(best_d) + " m off); curved quadratic tets are not supported");
        used[size_t(best)] = true;
        edges[size_t(k)] = t[size_t(4 + best)];
      }
      mesh.edges.push_back(edges);
    }
    if (n_attr > 0) {
      const auto at = size_t(1 + corners);
      const double r = p.real(line, at, "region attribute");
      if (!(r == std::floor(r) && std::abs(r) <= double(std::numeric_limits<int32_t>::max())))
        p.fail(line, "region attribute " + std::string(line.words[at]) + " of tet " + std::to_string(id) +
                         " is not an integer");
      mesh.region.push_back(int32_t(r));
    }
  }
}

std::ofstream open_for_writing(const std::string& path) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) throw MeshError(path + ": cannot open for writing");
  return out;
}

void finish_writing(std::ofstream& out, const std::string& path) {
  out.close();
  if (!out) throw MeshError(path + ": write failed");
}

std::string g17(double v) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.17g", v);
  return buf;
}

}  // namespace

SurfaceMesh read_surface(const std::string& path) {
  const std::string ext = lower(fs::path(path).extension().string());
  SurfaceMesh s;
  if (ext == ".off") {
    s = read_off(path);
  } else if (ext == ".obj" || ext == ".stl" || ext == ".ply") {
    if (ext == ".ply") {
      require_file(path);
      check_ply_counts(path);
    }
    s = read_with_assimp(path, ext == ".obj" ? "OBJ" : ext == ".stl" ? "STL" : "PLY");
  } else {
    throw MeshError(path + ": unknown surface mesh extension '" + fs::path(path).extension().string() +
                    "' (expected .obj, .stl, .off or .ply)");
  }
  if (s.triangles.empty()) throw MeshError(path + ": no triangles in file");
  return s;
}

TetMesh read_tetgen(const std::string& path) {
  std::string base = path;
  const std::string ext = lower(fs::path(path).extension().string());
  if (ext == ".node" || ext == ".ele") base = path.substr(0, path.size() - ext.size());
  const std::string node_path = base + ".node", ele_path = base + ".ele";
  const NodeFile nodes = read_node_file(node_path);
  TetMesh mesh;
  read_ele_file(ele_path, nodes, node_path, mesh);
  mesh.X = nodes.X;
  return mesh;
}

void write_tetgen(const TetMesh& mesh, const std::string& base) {
  const std::string node_path = base + ".node", ele_path = base + ".ele";
  {
    std::ofstream out = open_for_writing(node_path);
    out << "# tactile TetMesh: <node count> <dimension> <attributes> <boundary markers>\n";
    out << mesh.n_nodes() << " 3 0 0\n";
    for (int32_t i = 0; i < mesh.n_nodes(); ++i) {
      const Vec3& x = mesh.X[size_t(i)];
      out << i << ' ' << g17(x.x) << ' ' << g17(x.y) << ' ' << g17(x.z) << '\n';
    }
    finish_writing(out, node_path);
  }
  {
    const bool regions = !mesh.region.empty();
    std::ofstream out = open_for_writing(ele_path);
    out << "# tactile TetMesh: <tet count> <nodes per tet> <attributes (region id)>\n";
    out << mesh.n_tets() << ' ' << mesh.nodes_per_tet() << ' ' << (regions ? 1 : 0) << '\n';
    for (int32_t e = 0; e < mesh.n_tets(); ++e) {
      out << e;
      for (int k = 0; k < mesh.nodes_per_tet(); ++k) out << ' ' << mesh.node(size_t(e), k);
      if (regions) out << ' ' << mesh.region_of(e);
      out << '\n';
    }
    finish_writing(out, ele_path);
  }
}

void write_surface_obj(const SurfaceMesh& surface, const std::string& path) {
  std::ofstream out = open_for_writing(path);
  for (const Vec3& x : surface.vertices) out << "v " << g17(x.x) << ' ' << g17(x.y) << ' ' << g17(x.z) << '\n';
  for (const Tri& t : surface.triangles) out << "f " << t[0] + 1 << ' ' << t[1] + 1 << ' ' << t[2] + 1 << '\n';
  finish_writing(out, path);
}

}  // namespace tactile
