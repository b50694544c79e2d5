// Shared helpers of the app tests: a temporary folder, a strict little XML
// reader (to check that the VTU and PVD files are well-formed XML without a
// parser dependency in the build), base64 decoding, and file reading.
#pragma once

#include <gtest/gtest.h>

#include <cctype>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include <unistd.h>

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

struct XmlElement {
  std::string name;
  std::map<std::string, std::string> attributes;
  std::vector<XmlElement> children;
  std::string text;  // character data directly inside, whitespace kept

  const XmlElement& child(const std::string& n) const {
    for (const XmlElement& c : children)
      if (c.name == n) return c;
    throw std::runtime_error("<" + name + "> has no <" + n + ">");
  }
  const std::string& attr(const std::string& n) const {
    auto it = attributes.find(n);
    if (it == attributes.end()) throw std::runtime_error("<" + name + "> has no attribute " + n);
    return it->second;
  }
};

// Parses a document of elements, attributes and text (the XML subset VTK
// files use) and throws on anything malformed: unclosed or mismatched tags,
// duplicate or unquoted attributes, a bare '<' or '&' in text, trailing content.
class XmlReader {
 public:
  static XmlElement parse(const std::string& s) {
    XmlReader r(s);
    r.skip_space();
    if (r.starts("<?xml")) {
      const size_t end = s.find("?>", r.i_);
      if (end == std::string::npos) r.fail("unterminated XML declaration");
      r.i_ = end + 2;
    }
    r.skip_space();
    XmlElement root = r.element();
    r.skip_space();
    if (r.i_ != s.size()) r.fail("content after the root element");
    return root;
  }

 private:
  explicit XmlReader(const std::string& s) : s_(s) {}
  [[noreturn]] void fail(const std::string& what) const {
    throw std::runtime_error("XML error at byte " + std::to_string(i_) + ": " + what);
  }
  bool starts(const char* p) const { return s_.compare(i_, std::strlen(p), p) == 0; }
  void skip_space() {
    while (i_ < s_.size() && std::isspace(static_cast<unsigned char>(s_[i_]))) ++i_;
  }
  std::string name() {
    const size_t b = i_;
    while (i_ < s_.size() && (std::isalnum(static_cast<unsigned char>(s_[i_])) || s_[i_] == '_' || s_[i_] == ':' ||
                              s_[i_] == '-' || s_[i_] == '.'))
      ++i_;
    if (i_ == b) fail("expected a name");
    return s_.substr(b, i_ - b);
  }
  void check_text(const std::string& t) const {
    for (size_t k = 0; k < t.size(); ++k) {
      if (t[k] == '<') fail("'<' in text");
      if (t[k] == '&' && !(t.compare(k, 5, "&amp;") == 0 || t.compare(k, 4, "&lt;") == 0 ||
                           t.compare(k, 4, "&gt;") == 0 || t.compare(k, 6, "&quot;") == 0 ||
                           t.compare(k, 6, "&apos;") == 0))
        fail("bare '&' in text");
    }
  }
  XmlElement element() {
    if (i_ >= s_.size() || s_[i_] != '<') fail("expected '<'");
    ++i_;
    XmlElement e;
    e.name = name();
    for (;;) {
      const size_t before = i_;
      skip_space();
      if (starts("/>")) {
        i_ += 2;
        return e;
      }
      if (starts(">")) {
        ++i_;
        break;
      }
      if (i_ == before) fail("expected whitespace before an attribute");
      const std::string key = name();
      skip_space();
      if (!starts("=")) fail("expected '=' after " + key);
      ++i_;
      skip_space();
      if (i_ >= s_.size() || (s_[i_] != '"' && s_[i_] != '\'')) fail("unquoted attribute " + key);
      const char q = s_[i_++];
      const size_t end = s_.find(q, i_);
      if (end == std::string::npos) fail("unterminated attribute " + key);
      const std::string value = s_.substr(i_, end - i_);
      check_text(value);
      if (!e.attributes.emplace(key, value).second) fail("duplicate attribute " + key);
      i_ = end + 1;
    }
    for (;;) {
      const size_t lt = s_.find('<', i_);
      if (lt == std::string::npos) fail("<" + e.name + "> is not closed");
      const std::string text = s_.substr(i_, lt - i_);
      check_text(text);
      e.text += text;
      i_ = lt;
      if (starts("</")) {
        i_ += 2;
        if (name() != e.name) fail("mismatched end tag for <" + e.name + ">");
        skip_space();
        if (!starts(">")) fail("expected '>'");
        ++i_;
        return e;
      }
      e.children.push_back(element());
    }
  }

  const std::string& s_;
  size_t i_ = 0;
};

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

// Values of an inline binary VTK DataArray: base64 of [UInt64 byte count][values].
template <class T>
std::vector<T> decode_vtk_array(const XmlElement& a) {
  if (a.attr("format") != "binary") throw std::runtime_error("not a binary array");
  const std::vector<uint8_t> bytes = decode_base64(a.text);
  if (bytes.size() < 8) throw std::runtime_error("no header");
  uint64_t n = 0;
  std::memcpy(&n, bytes.data(), 8);
  if (n != bytes.size() - 8 || n % sizeof(T) != 0) throw std::runtime_error("byte count does not match the data");
  std::vector<T> out(n / sizeof(T));
  std::memcpy(out.data(), bytes.data() + 8, n);
  return out;
}

inline const XmlElement& find_array(const XmlElement& parent, const std::string& name) {
  for (const XmlElement& c : parent.children)
    if (c.name == "DataArray" && c.attributes.count("Name") && c.attr("Name") == name) return c;
  throw std::runtime_error("no DataArray " + name);
}

}  // namespace tactile::test
