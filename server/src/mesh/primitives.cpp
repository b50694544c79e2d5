#include "mesh/primitives.hpp"

#include <algorithm>
#include <cmath>
#include <map>
#include <numbers>
#include <string>
#include <utility>

#include "mesh/mesh_error.hpp"
#include "mesh/tetgen.hpp"

namespace tactile {
namespace {

// (1 - t) lo + t hi: exactly lo at t = 0 and exactly hi at t = 1.
double lerp(double lo, double hi, double t) { return (1.0 - t) * lo + t * hi; }

// Swaps two nodes of tets with negative volume. Only for tets known to be
// non-degenerate, where the sign is unambiguous.
void orient_positive(TetMesh& mesh) {
  for (Tet& t : mesh.tets) {
    const auto& X = mesh.X;
    if (compute_tet_volume(X[size_t(t[0])], X[size_t(t[1])], X[size_t(t[2])], X[size_t(t[3])]) < 0.0)
      std::swap(t[1], t[2]);
  }
}

}  // namespace

TetMesh make_box(const Vec3& lo, const Vec3& hi, std::array<int, 3> cells, BoxSplit split) {
  const auto [nx, ny, nz] = cells;
  if (nx < 1 || ny < 1 || nz < 1)
    throw MeshError("make_box: cells must be >= 1 in each direction, got (" + std::to_string(nx) + ", " +
                    std::to_string(ny) + ", " + std::to_string(nz) + ")");
  for (int d = 0; d < 3; ++d) {
    if (!std::isfinite(lo[d]) || !std::isfinite(hi[d]) || !(hi[d] > lo[d]))
      throw MeshError("make_box: need finite lo < hi in each direction; axis " + std::to_string(d) + " has lo " +
                      std::to_string(lo[d]) + ", hi " + std::to_string(hi[d]));
  }

  TetMesh mesh;
  auto grid = [&](int i, int j, int k) { return int32_t(i + (nx + 1) * (j + (ny + 1) * k)); };
  mesh.X.reserve(size_t(nx + 1) * size_t(ny + 1) * size_t(nz + 1));
  for (int k = 0; k <= nz; ++k)
    for (int j = 0; j <= ny; ++j)
      for (int i = 0; i <= nx; ++i)
        mesh.X.emplace_back(lerp(lo.x, hi.x, double(i) / nx), lerp(lo.y, hi.y, double(j) / ny),
                            lerp(lo.z, hi.z, double(k) / nz));

  if (split == BoxSplit::kuhn6) {
    // One tet per path 000 -> 111 along the axes in the order of a
    // permutation; det[e_a, e_b, e_c] is the permutation's sign, so odd
    // permutations get two nodes swapped.
    static constexpr int kPerm[6][3] = {{0, 1, 2}, {1, 2, 0}, {2, 0, 1}, {0, 2, 1}, {2, 1, 0}, {1, 0, 2}};
    mesh.tets.reserve(size_t(nx) * size_t(ny) * size_t(nz) * 6);
    for (int k = 0; k < nz; ++k)
      for (int j = 0; j < ny; ++j)
        for (int i = 0; i < nx; ++i)
          for (int p = 0; p < 6; ++p) {
            std::array<int, 3> c{i, j, k};
            Tet t{};
            t[0] = grid(c[0], c[1], c[2]);
            for (int s = 0; s < 3; ++s) {
              ++c[size_t(kPerm[p][s])];
              t[size_t(s + 1)] = grid(c[0], c[1], c[2]);
            }
            if (p >= 3) std::swap(t[1], t[2]);
            mesh.tets.push_back(t);
          }
    return mesh;
  }

  // centred24: face-centre nodes (x-, y-, z-normal faces), then cell centres.
  const std::array<int, 3> n{nx, ny, nz};
  std::array<int32_t, 3> face_base{};
  int32_t next = mesh.n_nodes();
  for (int d = 0; d < 3; ++d) {
    face_base[size_t(d)] = next;
    std::array<int, 3> m = n;
    ++m[size_t(d)];
    next += m[0] * m[1] * m[2];
  }
  const int32_t centre_base = next;
  // Face node of the d-normal face whose lowest corner is grid node c.
  auto face_node = [&](int d, const std::array<int, 3>& c) {
    std::array<int, 3> m = n;
    ++m[size_t(d)];
    return face_base[size_t(d)] + c[0] + m[0] * (c[1] + m[1] * c[2]);
  };
  auto at = [&](const std::array<int, 3>& c) { return grid(c[0], c[1], c[2]); };

  mesh.X.resize(size_t(centre_base) + size_t(nx) * size_t(ny) * size_t(nz));
  for (int d = 0; d < 3; ++d) {
    const int u = (d + 1) % 3, v = (d + 2) % 3;
    std::array<int, 3> m = n;
    ++m[size_t(d)];
    for (int k = 0; k < m[2]; ++k)
      for (int j = 0; j < m[1]; ++j)
        for (int i = 0; i < m[0]; ++i) {
          std::array<int, 3> c{i, j, k};
          Vec3 sum{0.0};
          for (int a = 0; a < 2; ++a)
            for (int b = 0; b < 2; ++b) {
              std::array<int, 3> q = c;
              q[size_t(u)] += a;
              q[size_t(v)] += b;
              sum += mesh.X[size_t(at(q))];
            }
          mesh.X[size_t(face_node(d, c))] = 0.25 * sum;
        }
  }
  mesh.tets.reserve(size_t(nx) * size_t(ny) * size_t(nz) * 24);
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) {
        const std::array<int, 3> c{i, j, k};
        const int32_t centre = centre_base + i + nx * (j + ny * k);
        mesh.X[size_t(centre)] = 0.5 * (mesh.X[size_t(grid(i, j, k))] + mesh.X[size_t(grid(i + 1, j + 1, k + 1))]);
        for (int d = 0; d < 3; ++d) {
          const int u = (d + 1) % 3, v = (d + 2) % 3;
          for (int side = 0; side < 2; ++side) {
            std::array<int, 3> f = c;
            f[size_t(d)] += side;
            // The face's corners in cyclic order.
            std::array<int32_t, 4> ring{};
            static constexpr int kUv[4][2] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
            for (int r = 0; r < 4; ++r) {
              std::array<int, 3> q = f;
              q[size_t(u)] += kUv[r][0];
              q[size_t(v)] += kUv[r][1];
              ring[size_t(r)] = at(q);
            }
            const int32_t fc = face_node(d, f);
            for (int r = 0; r < 4; ++r) mesh.tets.push_back({ring[size_t(r)], ring[size_t((r + 1) % 4)], fc, centre});
          }
        }
      }
  orient_positive(mesh);
  return mesh;
}

TetMesh make_cylinder(double radius, double height, int n_around, int n_height, int n_radial) {
  if (!(radius > 0.0) || !(height > 0.0) || !std::isfinite(radius) || !std::isfinite(height))
    throw MeshError("make_cylinder: radius and height must be finite and > 0, got " + std::to_string(radius) + ", " +
                    std::to_string(height));
  if (n_around < 3 || n_height < 1 || n_radial < 1)
    throw MeshError("make_cylinder: need n_around >= 3, n_height >= 1, n_radial >= 1, got " + std::to_string(n_around) +
                    ", " + std::to_string(n_height) + ", " + std::to_string(n_radial));

  // Cross-section in the x-z plane: a centre node, then rings k = 1..n_radial
  // of m_k = max(3, ceil(n_around k / n_radial)) nodes at radius r k / n_radial,
  // the outer ring with exactly n_around.
  struct P2 {
    double x, z;
  };
  std::vector<P2> disc{{0.0, 0.0}};
  std::vector<std::array<int32_t, 3>> tris;  // disc triangles, all wound the same way (checked below)
  std::vector<int32_t> prev{0};              // node ids of the previous ring (the centre first)
  for (int k = 1; k <= n_radial; ++k) {
    const int m = std::max(3, (n_around * k + n_radial - 1) / n_radial);
    const double r = k == n_radial ? radius : radius * k / n_radial;
    std::vector<int32_t> ring;
    for (int a = 0; a < m; ++a) {
      const double th = 2.0 * std::numbers::pi * a / m;
      ring.push_back(int32_t(disc.size()));
      disc.push_back({r * std::cos(th), r * std::sin(th)});
    }
    const auto mi = int(prev.size()), mo = m;
    if (mi == 1) {
      for (int a = 0; a < mo; ++a) tris.push_back({prev[0], ring[size_t(a)], ring[size_t((a + 1) % mo)]});
    } else {
      // Merge the two rings by angle: advance the ring whose next node comes
      // first (integer comparison of a/mi and b/mo keeps it exact).
      int a = 0, b = 0;
      while (a < mi || b < mo) {
        if (b == mo || (a < mi && (a + 1) * mo <= (b + 1) * mi)) {
          tris.push_back({prev[size_t(a)], ring[size_t(b % mo)], prev[size_t((a + 1) % mi)]});
          ++a;
        } else {
          tris.push_back({prev[size_t(a % mi)], ring[size_t(b)], ring[size_t((b + 1) % mo)]});
          ++b;
        }
      }
    }
    prev = std::move(ring);
  }
  // Every triangle must wind the same way; a reversed one means the rings
  // overlap (too many rings for too few sides).
  for (const auto& t : tris) {
    const P2 &p = disc[size_t(t[0])], &q = disc[size_t(t[1])], &s = disc[size_t(t[2])];
    const double area2 = (q.x - p.x) * (s.z - p.z) - (q.z - p.z) * (s.x - p.x);
    if (!(area2 > 0.0))
      throw MeshError("make_cylinder: n_radial = " + std::to_string(n_radial) +
                      " is too large for n_around = " + std::to_string(n_around) + " (rings overlap)");
  }

  TetMesh mesh;
  const auto nd = int32_t(disc.size());
  mesh.X.reserve(size_t(nd) * size_t(n_height + 1));
  for (int l = 0; l <= n_height; ++l) {
    const double y = lerp(0.0, height, double(l) / n_height);
    for (const P2& p : disc) mesh.X.emplace_back(p.x, y, p.z);
  }
  // Prism (a, b, c) x layer -> 3 tets. With a < b < c by id, each side quad's
  // diagonal runs from the lower id at the bottom to the higher id at the top,
  // a rule that depends on the quad alone, so neighbouring prisms conform.
  mesh.tets.reserve(tris.size() * size_t(n_height) * 3);
  for (int l = 0; l < n_height; ++l) {
    for (auto t : tris) {
      std::sort(t.begin(), t.end());
      const int32_t a = t[0] + l * nd, b = t[1] + l * nd, c = t[2] + l * nd;
      const int32_t A = a + nd, B = b + nd, C = c + nd;
      mesh.tets.push_back({a, b, c, C});
      mesh.tets.push_back({a, b, B, C});
      mesh.tets.push_back({a, A, B, C});
    }
  }
  orient_positive(mesh);
  return mesh;
}

TetMesh make_sphere(const Vec3& centre, double radius, int resolution) {
  if (!(radius > 0.0) || !std::isfinite(radius) || !std::isfinite(centre.x) || !std::isfinite(centre.y) ||
      !std::isfinite(centre.z))
    throw MeshError("make_sphere: need a finite centre and a finite radius > 0, got radius " + std::to_string(radius));
  if (resolution < 0 || resolution > 6)
    throw MeshError("make_sphere: resolution must be in 0..6, got " + std::to_string(resolution));

  // Icosahedron: vertices (0, +-1, +-phi) and their cyclic permutations.
  const double g = std::numbers::phi;
  std::vector<Vec3> unit = {{-1, g, 0},  {1, g, 0},  {-1, -g, 0}, {1, -g, 0}, {0, -1, g},  {0, 1, g},
                            {0, -1, -g}, {0, 1, -g}, {g, 0, -1},  {g, 0, 1},  {-g, 0, -1}, {-g, 0, 1}};
  for (Vec3& p : unit) p /= std::sqrt(1.0 + g * g);
  std::vector<Tri> tris = {{0, 11, 5},  {0, 5, 1},  {0, 1, 7},  {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
                           {11, 10, 2}, {10, 7, 6}, {7, 1, 8},  {3, 9, 4},  {3, 4, 2},   {3, 2, 6}, {3, 6, 8},
                           {3, 8, 9},   {4, 9, 5},  {2, 4, 11}, {6, 2, 10}, {8, 6, 7},   {9, 8, 1}};
  for (int level = 0; level < resolution; ++level) {
    std::map<std::pair<int32_t, int32_t>, int32_t> midpoint;
    auto mid = [&](int32_t a, int32_t b) {
      const auto key = std::minmax(a, b);
      auto [it, inserted] = midpoint.try_emplace(key, int32_t(unit.size()));
      if (inserted) {
        const Vec3 m = unit[size_t(a)] + unit[size_t(b)];
        unit.push_back(m / std::sqrt(m.x * m.x + m.y * m.y + m.z * m.z));
      }
      return it->second;
    };
    std::vector<Tri> finer;
    finer.reserve(tris.size() * 4);
    for (const Tri& t : tris) {
      const int32_t ab = mid(t[0], t[1]), bc = mid(t[1], t[2]), ca = mid(t[2], t[0]);
      finer.push_back({t[0], ab, ca});
      finer.push_back({t[1], bc, ab});
      finer.push_back({t[2], ca, bc});
      finer.push_back({ab, bc, ca});
    }
    tris = std::move(finer);
  }

  SurfaceMesh surface;
  surface.triangles = tris;
  surface.vertices.reserve(unit.size());
  for (const Vec3& p : unit) surface.vertices.push_back(centre + radius * p);

  // Interior tets about the size of a regular tet on the mean surface edge.
  double edge_sum = 0.0;
  for (const Tri& t : tris) {
    for (int e = 0; e < 3; ++e) {
      const Vec3 d = surface.vertices[size_t(t[size_t(e)])] - surface.vertices[size_t(t[size_t((e + 1) % 3)])];
      edge_sum += std::sqrt(d.x * d.x + d.y * d.y + d.z * d.z);
    }
  }
  const double h = edge_sum / double(3 * tris.size());
  TetgenOptions options;
  options.max_volume = h * h * h / (6.0 * std::numbers::sqrt2);
  return tetrahedralize(surface, options);
}

}  // namespace tactile
