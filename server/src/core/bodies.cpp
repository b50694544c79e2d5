#include "core/bodies.hpp"

#include "core/model.hpp"

#include <glm/geometric.hpp>

namespace tactile {

void append_embedded(EmbeddedSurface& a, const EmbeddedSurface& b, int32_t node_offset, int32_t tet_offset) {
  const auto v0 = int32_t(a.rest.vertices.size());
  a.rest.vertices.insert(a.rest.vertices.end(), b.rest.vertices.begin(), b.rest.vertices.end());
  for (Tri t : b.rest.triangles) {
    for (int32_t& v : t) v += v0;
    a.rest.triangles.push_back(t);
  }
  for (Tet t : b.nodes) {
    for (int32_t& n : t) n += node_offset;
    a.nodes.push_back(t);
  }
  a.weights.insert(a.weights.end(), b.weights.begin(), b.weights.end());
  for (int32_t e : b.tet) a.tet.push_back(e + tet_offset);
  a.outside.insert(a.outside.end(), b.outside.begin(), b.outside.end());
}

void add_bodies(ModelSpec& spec, std::vector<BodyParts> bodies) {
  bool any_surface = false;
  for (const BodyParts& b : bodies) any_surface = any_surface || b.surface != nullptr;
  auto surface = any_surface ? std::make_shared<EmbeddedSurface>() : nullptr;
  for (size_t i = 0; i < bodies.size(); ++i) {
    BodyParts& b = bodies[i];
    const std::string name = "body " + std::to_string(i) + " ('" + b.name + "')";
    if (i > 0 && b.mesh.quadratic() != bodies[0].mesh.quadratic())
      throw ModelError(name + ": its element order differs from body 0's; the bodies of a scene share one");
    BodySpec body;
    body.name = b.name;
    body.node_begin = spec.mesh.n_nodes();
    body.tet_begin = spec.mesh.n_tets();
    const auto region0 = int32_t(spec.materials.size());
    spec.mesh.X.insert(spec.mesh.X.end(), b.mesh.X.begin(), b.mesh.X.end());
    for (int32_t e = 0; e < b.mesh.n_tets(); ++e) {
      Tet t = b.mesh.tets[size_t(e)];
      for (int32_t& n : t) n += body.node_begin;
      spec.mesh.tets.push_back(t);
      if (b.mesh.quadratic()) {
        TetEdges edges = b.mesh.edges[size_t(e)];
        for (int32_t& n : edges) n += body.node_begin;
        spec.mesh.edges.push_back(edges);
      }
      spec.mesh.region.push_back(region0 + b.mesh.region_of(e));
    }
    body.node_end = spec.mesh.n_nodes();
    body.tet_end = spec.mesh.n_tets();
    spec.materials.insert(spec.materials.end(), b.materials.begin(), b.materials.end());
    body.material_begin = region0;
    body.material_end = int32_t(spec.materials.size());
    for (EssentialBc bc : b.essential) {
      bc.where.first = body.node_begin;
      bc.where.count = body.node_end - body.node_begin;
      spec.essential.push_back(std::move(bc));
    }
    for (NaturalLoad load : b.loads) {
      load.where.first = body.node_begin;
      load.where.count = body.node_end - body.node_begin;
      spec.loads.push_back(std::move(load));
    }
    if (surface) {
      body.fine_vertex_begin = surface->n_vertices();
      body.fine_triangle_begin = int32_t(surface->rest.triangles.size());
      if (b.surface) {
        append_embedded(*surface, *b.surface, body.node_begin, body.tet_begin);
      } else {
        // Its boundary as a fine surface: the nodes on it, by their positions.
        SurfaceMesh boundary;
        const std::vector<Tri> faces = compute_boundary_faces(b.mesh);
        const std::vector<int32_t> nodes = compute_boundary_nodes(faces);
        std::vector<int32_t> vertex_of(b.mesh.X.size(), -1);
        for (int32_t n : nodes) {
          vertex_of[size_t(n)] = int32_t(boundary.vertices.size());
          boundary.vertices.push_back(b.mesh.X[size_t(n)]);
        }
        for (const Tri& f : faces)
          boundary.triangles.push_back({vertex_of[size_t(f[0])], vertex_of[size_t(f[1])], vertex_of[size_t(f[2])]});
        // (Each vertex is a node of the mesh: bound to within rounding.)
        const double tolerance = 1e-9 * glm::length(compute_aabb(b.mesh.X).size());
        append_embedded(*surface, embed_surface(b.mesh, std::move(boundary), tolerance), body.node_begin,
                        body.tet_begin);
      }
      body.fine_vertex_end = surface->n_vertices();
      body.fine_triangle_end = int32_t(surface->rest.triangles.size());
    }
    spec.bodies.push_back(body);
  }
  spec.surface = surface;
}

}  // namespace tactile
