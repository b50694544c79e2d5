// Shared helpers of the app tests: a temporary folder, file reading, and the
// reading of our VTU and PVD files: XML through pugixml, then base64 and VTK's
// binary arrays.
#pragma once

#include <gtest/gtest.h>

#include <cctype>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include <unistd.h>

#include <pugixml.hpp>

#include "temp_dir.hpp"

namespace tactile::test {

inline std::string read_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error(path + ": cannot open");
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

inline void write_file(const std::string& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out << text;
}

// An XML file parsed by pugixml (Debian: libpugixml-dev); throws, naming the
// file, the byte and what is wrong, unless it is well-formed XML with one root
// element (pugixml itself accepts several).
inline pugi::xml_document read_xml(const std::string& path) {
  pugi::xml_document doc;
  const pugi::xml_parse_result r = doc.load_file(path.c_str());
  if (!r) throw std::runtime_error(path + ": XML error at byte " + std::to_string(r.offset) + ": " + r.description());
  size_t roots = 0;
  for (pugi::xml_node n : doc.children()) roots += n.type() == pugi::node_element ? 1 : 0;
  if (roots != 1) throw std::runtime_error(path + ": " + std::to_string(roots) + " root elements");
  return doc;
}

// The element children of `parent`, in order (a PVD's DataSets).
inline std::vector<pugi::xml_node> elements(pugi::xml_node parent) {
  std::vector<pugi::xml_node> out;
  for (pugi::xml_node n : parent.children())
    if (n.type() == pugi::node_element) out.push_back(n);
  return out;
}

inline std::vector<uint8_t> decode_base64(const std::string& text) {
  auto value = [](char c) -> int {
    if (c >= 'A' && c <= 'Z') return c - 'A';
    if (c >= 'a' && c <= 'z') return c - 'a' + 26;
    if (c >= '0' && c <= '9') return c - '0' + 52;
    if (c == '+') return 62;
    if (c == '/') return 63;
    return -1;
  };
  std::vector<uint8_t> out;
  uint32_t acc = 0;
  int bits = 0;
  for (char c : text) {
    if (std::isspace(static_cast<unsigned char>(c)) || c == '=') continue;
    const int v = value(c);
    if (v < 0) throw std::runtime_error(std::string("not base64: '") + c + "'");
    acc = (acc << 6) | uint32_t(v);
    bits += 6;
    if (bits >= 8) {
      bits -= 8;
      out.push_back(uint8_t((acc >> bits) & 0xFF));
    }
  }
  return out;
}

// The DataArray of `parent` named `name`; throws when there is none.
inline pugi::xml_node find_array(pugi::xml_node parent, const std::string& name) {
  const pugi::xml_node a = parent.find_child_by_attribute("DataArray", "Name", name.c_str());
  if (!a) throw std::runtime_error("<" + std::string(parent.name()) + "> has no DataArray " + name);
  return a;
}

// Values of an inline binary VTK DataArray: base64 of [UInt64 byte count][values].
template <class T>
std::vector<T> decode_vtk_array(pugi::xml_node a) {
  if (std::string(a.attribute("format").value()) != "binary") throw std::runtime_error("not a binary array");
  const std::vector<uint8_t> bytes = decode_base64(a.child_value());
  if (bytes.size() < 8) throw std::runtime_error("no header");
  uint64_t n = 0;
  std::memcpy(&n, bytes.data(), 8);
  if (n != bytes.size() - 8 || n % sizeof(T) != 0) throw std::runtime_error("byte count does not match the data");
  std::vector<T> out(n / sizeof(T));
  std::memcpy(out.data(), bytes.data() + 8, n);
  return out;
}

}  // namespace tactile::test
