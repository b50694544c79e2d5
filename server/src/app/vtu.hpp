// ParaView output: VTK XML unstructured grids (.vtu), one per frame, and a
// .pvd collection that gives each its time. Written by hand (the format is
// small and VTK is a heavy dependency): inline base64 binary arrays, each
// preceded by its byte count as UInt64, as VTK itself writes them.
#pragma once

#include <string>
#include <vector>

#include "core/mesh.hpp"

namespace tactile {

// One frame of a body; arrays in double, node arrays (n_nodes x 3).
struct VtuFrame {
  const TetMesh* mesh = nullptr;
  const std::vector<double>* u = nullptr;               // displacement [m]; points are X + u
  const std::vector<double>* v = nullptr;               // velocity [m/s]
  const std::vector<double>* energy_density = nullptr;  // strain-energy density per tet [J/m^3] (n_tets)
};

// Writes `path` (throws std::runtime_error when it cannot).
void write_vtu(const std::string& path, const VtuFrame& frame);

struct PvdEntry {
  double t;          // [s]
  std::string file;  // relative to the .pvd
};
void write_pvd(const std::string& path, const std::vector<PvdEntry>& entries);

// RFC 4648 base64 (with padding), as VTK's binary arrays use.
std::string encode_base64(const void* data, size_t n_bytes);

}  // namespace tactile
