#include "mesh/tetgen.hpp"

#include <tetgen.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <string>
#include <utility>

#include "mesh/mesh_error.hpp"

namespace tactile {

extern const bool kTetgenTerminateReplaced;  // tetgen_terminate.cpp

namespace {

std::string format_vec(const Vec3& p) {
  char buf[96];
  std::snprintf(buf, sizeof buf, "(%.9g, %.9g, %.9g)", p.x, p.y, p.z);
  return buf;
}

// Switch numbers as TetGen parses them: digits, '.', 'e', '+', '-'.
std::string format_switch_number(double v) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.17g", v);
  return buf;
}

void check_surface(const SurfaceMesh& s) {
  if (s.vertices.size() < 4 || s.triangles.size() < 4)
    throw MeshError("tetrahedralize: surface has " + std::to_string(s.vertices.size()) + " vertices and " +
                    std::to_string(s.triangles.size()) + " triangles; a closed surface needs at least 4 of each");
  for (size_t i = 0; i < s.vertices.size(); ++i) {
    const Vec3& p = s.vertices[i];
    if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z))
      throw MeshError("tetrahedralize: surface vertex " + std::to_string(i) + " has a non-finite coordinate");
  }
  const auto n = int32_t(s.vertices.size());
  for (size_t f = 0; f < s.triangles.size(); ++f) {
    const Tri& t = s.triangles[f];
    for (int32_t v : t) {
      if (v < 0 || v >= n)
        throw MeshError("tetrahedralize: triangle " + std::to_string(f) + " refers to vertex " + std::to_string(v) +
                        ", outside 0.." + std::to_string(n - 1));
    }
    if (t[0] == t[1] || t[1] == t[2] || t[2] == t[0])
      throw MeshError("tetrahedralize: triangle " + std::to_string(f) + " repeats a vertex (" + std::to_string(t[0]) +
                      ", " + std::to_string(t[1]) + ", " + std::to_string(t[2]) + ")");
  }
  // Closed: every edge in exactly two triangles. The first bad edge in
  // triangle order is named, with its coordinates, to find it in a viewer.
  std::map<std::pair<int32_t, int32_t>, int> uses;
  for (const Tri& t : s.triangles)
    for (int e = 0; e < 3; ++e) ++uses[std::minmax(t[size_t(e)], t[size_t((e + 1) % 3)])];
  for (size_t f = 0; f < s.triangles.size(); ++f) {
    const Tri& t = s.triangles[f];
    for (int e = 0; e < 3; ++e) {
      const auto edge = std::minmax(t[size_t(e)], t[size_t((e + 1) % 3)]);
      const int count = uses[edge];
      if (count == 2) continue;
      throw MeshError("tetrahedralize: surface is not closed: edge (" + std::to_string(edge.first) + ", " +
                      std::to_string(edge.second) + ") from " + format_vec(s.vertices[size_t(edge.first)]) + " to " +
                      format_vec(s.vertices[size_t(edge.second)]) + " is used by " + std::to_string(count) +
                      (count == 1 ? " triangle" : " triangles") + " (first: triangle " + std::to_string(f) +
                      "); every edge must be shared by exactly 2");
    }
  }
}

void check_options(const TetgenOptions& o) {
  if (!(o.max_radius_edge_ratio == 0.0 || (o.max_radius_edge_ratio >= 1.0 && std::isfinite(o.max_radius_edge_ratio))))
    throw MeshError("tetrahedralize: max_radius_edge_ratio must be 0 (off) or >= 1, got " +
                    std::to_string(o.max_radius_edge_ratio));
  if (!(o.min_dihedral_deg >= 0.0 && o.min_dihedral_deg < 60.0))
    throw MeshError("tetrahedralize: min_dihedral_deg must be in [0, 60), got " + std::to_string(o.min_dihedral_deg));
  if (o.min_dihedral_deg > 0.0 && o.max_radius_edge_ratio == 0.0)
    throw MeshError("tetrahedralize: min_dihedral_deg needs max_radius_edge_ratio > 0 (both are TetGen -q)");
  if (!(o.max_volume >= 0.0 && std::isfinite(o.max_volume)))
    throw MeshError("tetrahedralize: max_volume must be finite and >= 0, got " + std::to_string(o.max_volume));
}

// Fills `in` with the surface as a piecewise linear complex, one facet per triangle.
void fill_tetgenio(const SurfaceMesh& s, tetgenio& in) {
  in.firstnumber = 0;
  in.numberofpoints = int(s.vertices.size());
  in.pointlist = new REAL[s.vertices.size() * 3];
  for (size_t i = 0; i < s.vertices.size(); ++i) {
    in.pointlist[3 * i + 0] = s.vertices[i].x;
    in.pointlist[3 * i + 1] = s.vertices[i].y;
    in.pointlist[3 * i + 2] = s.vertices[i].z;
  }
  in.numberoffacets = int(s.triangles.size());
  in.facetlist = new tetgenio::facet[s.triangles.size()];
  for (size_t f = 0; f < s.triangles.size(); ++f) {
    tetgenio::facet& facet = in.facetlist[f];
    tetgenio::init(&facet);
    facet.numberofpolygons = 1;
    facet.polygonlist = new tetgenio::polygon[1];
    tetgenio::init(&facet.polygonlist[0]);
    facet.polygonlist[0].numberofvertices = 3;
    facet.polygonlist[0].vertexlist = new int[3];
    for (size_t k = 0; k < 3; ++k) facet.polygonlist[0].vertexlist[k] = s.triangles[f][k];
  }
}

// TetGen's exit codes (terminatetetgen) in words.
std::string describe_tetgen_code(int code) {
  switch (code) {
    case 1: return "out of memory";
    case 2: return "internal error";
    case 3: return "the surface intersects itself";
    case 4: return "a very small input feature size was detected (features below TetGen's tolerance)";
    case 5: return "two very close input facets were detected";
    case 10: return "input error (invalid surface or switches)";
    default: return "error code " + std::to_string(code);
  }
}

// TetGen -d: reports the surface's intersecting triangles as output faces.
// Returns "N triangles cross others: ids", or "" when TetGen finds none.
std::string find_self_intersection(const SurfaceMesh& s) {
  tetgenio in, out;
  fill_tetgenio(s, in);
  std::string switches = "pdzQ";
  try {
    ::tetrahedralize(switches.data(), &in, &out);
  } catch (int) {
    return "";
  }
  std::map<std::array<int32_t, 3>, size_t> id_of;
  for (size_t f = 0; f < s.triangles.size(); ++f) {
    Tri key = s.triangles[f];
    std::sort(key.begin(), key.end());
    id_of.emplace(key, f);
  }
  // TetGen lists the crossing triangles, not the pairs.
  std::string ids;
  for (int i = 0; i < out.numberoftrifaces && i < 6; ++i) {
    Tri key{out.trifacelist[3 * i], out.trifacelist[3 * i + 1], out.trifacelist[3 * i + 2]};
    std::sort(key.begin(), key.end());
    auto it = id_of.find(key);
    ids += i ? ", " : "";
    ids += it != id_of.end() ? std::to_string(it->second)
                             : "(on vertices " + std::to_string(key[0]) + ", " + std::to_string(key[1]) + ", " +
                                   std::to_string(key[2]) + ")";
  }
  if (ids.empty()) return "";
  if (out.numberoftrifaces > 6) ids += ", ...";
  return std::to_string(out.numberoftrifaces) + " triangles cross others: " + ids;
}

}  // namespace

TetMesh tetrahedralize(const SurfaceMesh& surface, const TetgenOptions& options) {
  if (!kTetgenTerminateReplaced) throw MeshError("tetrahedralize: TetGen's error exit is not replaced");
  check_options(options);
  check_surface(surface);

  std::string switches = "p";
  if (options.max_radius_edge_ratio > 0.0) {
    // Appended piecewise: GCC 12 warns falsely (-Wrestrict) on "q" + std::string.
    switches += 'q';
    switches += format_switch_number(options.max_radius_edge_ratio);
    if (options.min_dihedral_deg > 0.0) {
      switches += '/';
      switches += format_switch_number(options.min_dihedral_deg);
    }
  }
  if (options.max_volume > 0.0) {
    switches += 'a';
    switches += format_switch_number(options.max_volume);
  }
  switches += "z";  // number output from 0
  if (options.quiet) switches += "Q";

  tetgenio in, out;
  fill_tetgenio(surface, in);
  try {
    ::tetrahedralize(switches.data(), &in, &out);
  } catch (int code) {
    std::string msg = "tetrahedralize: TetGen (-" + switches + ") failed: " + describe_tetgen_code(code);
    if (code == 3) {
      const std::string where = find_self_intersection(surface);
      if (!where.empty()) msg += ": " + where;
    }
    throw MeshError(msg);
  }
  if (out.numberoftetrahedra <= 0 || out.numberofpoints < 4 || out.numberofcorners < 4)
    throw MeshError("tetrahedralize: TetGen (-" + switches + ") returned no tetrahedra");

  TetMesh mesh;
  mesh.X.resize(size_t(out.numberofpoints));
  for (size_t i = 0; i < mesh.X.size(); ++i)
    mesh.X[i] = Vec3(out.pointlist[3 * i], out.pointlist[3 * i + 1], out.pointlist[3 * i + 2]);
  const auto corners = size_t(out.numberofcorners);
  mesh.tets.resize(size_t(out.numberoftetrahedra));
  for (size_t e = 0; e < mesh.tets.size(); ++e) {
    Tet& t = mesh.tets[e];
    for (size_t k = 0; k < 4; ++k) {
      t[k] = out.tetrahedronlist[e * corners + k];
      if (t[k] < 0 || t[k] >= mesh.n_nodes())
        throw MeshError("tetrahedralize: TetGen returned tet " + std::to_string(e) + " with node " +
                        std::to_string(t[k]) + ", outside 0.." + std::to_string(mesh.n_nodes() - 1));
    }
    if (compute_tet_volume(mesh.X[size_t(t[0])], mesh.X[size_t(t[1])], mesh.X[size_t(t[2])], mesh.X[size_t(t[3])]) <
        0.0)
      std::swap(t[1], t[2]);
  }
  return mesh;
}

}  // namespace tactile
