#include "scene/json_fields.hpp"

#include <cmath>
#include <cstdio>
#include <limits>

#include <glm/geometric.hpp>

namespace tactile::scene_json {

void Origin::fail(const std::string& path, const std::string& what) const {
  std::string msg = file + ": ";
  if (!variant.empty()) msg += "variant '" + variant + "': ";
  if (!path.empty()) msg += path + ": ";
  throw SceneError(msg + what);
}

std::string join(const std::string& path, std::string_view key) {
  return path.empty() ? std::string(key) : path + "." + std::string(key);
}

std::string join(const std::string& path, size_t i) { return path + "[" + std::to_string(i) + "]"; }

std::string describe(const Json& v) {
  switch (v.type()) {
    case Json::value_t::object: return "an object";
    case Json::value_t::array: return "an array of " + std::to_string(v.size());
    case Json::value_t::null: return "null";
    default: break;
  }
  std::string s = v.dump();
  if (s.size() > 40) s = s.substr(0, 37) + "...";
  return s;
}

namespace {

std::string list(std::initializer_list<std::string_view> names, const char* quote) {
  std::string s;
  for (std::string_view n : names) s += (s.empty() ? "" : ", ") + std::string(quote) + std::string(n) + quote;
  return s;
}

bool is_number(const Json& v) { return v.is_number(); }  // booleans are not numbers in nlohmann

std::string format(double x) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", x);
  return buf;
}

}  // namespace

Fields::Fields(const Json& j, std::string path, const Origin& origin, std::initializer_list<std::string_view> allowed)
    : j_(j), path_(std::move(path)), origin_(origin) {
  if (!j.is_object()) origin.fail(path_, "must be an object, got " + describe(j));
  for (const auto& item : j.items()) {
    bool known = false;
    for (std::string_view a : allowed) known = known || item.key() == a;
    if (!known) origin.fail(join(path_, item.key()), "unknown field (allowed here: " + list(allowed, "") + ")");
  }
}

const Json& Fields::at(std::string_view key) const {
  const Json* v = find(key);
  if (!v) origin_.fail(path(key), "required field missing");
  return *v;
}

const Json* Fields::find(std::string_view key) const {
  auto it = j_.find(key);
  return it == j_.end() ? nullptr : &*it;
}

double Fields::number(std::string_view key) const { return read_number(at(key), path(key), origin_); }
double Fields::positive(std::string_view key) const { return read_positive(at(key), path(key), origin_); }
double Fields::non_negative(std::string_view key) const { return read_non_negative(at(key), path(key), origin_); }
int64_t Fields::integer(std::string_view key, int64_t lo, int64_t hi) const {
  return read_integer(at(key), path(key), origin_, lo, hi);
}
Vec3 Fields::vec3(std::string_view key) const { return read_vec3(at(key), path(key), origin_); }
std::string Fields::string(std::string_view key) const { return read_string(at(key), path(key), origin_); }

double Fields::number_or(std::string_view key, double fallback) const { return has(key) ? number(key) : fallback; }
double Fields::positive_or(std::string_view key, double fallback) const { return has(key) ? positive(key) : fallback; }
double Fields::non_negative_or(std::string_view key, double fallback) const {
  return has(key) ? non_negative(key) : fallback;
}
int64_t Fields::integer_or(std::string_view key, int64_t lo, int64_t hi, int64_t fallback) const {
  return has(key) ? integer(key, lo, hi) : fallback;
}
std::string Fields::string_or(std::string_view key, const std::string& fallback) const {
  return has(key) ? string(key) : fallback;
}

double read_number(const Json& v, const std::string& path, const Origin& o) {
  if (!is_number(v)) o.fail(path, "must be a number, got " + describe(v));
  const double x = v.get<double>();
  if (!std::isfinite(x)) o.fail(path, "must be finite, got " + describe(v));
  return x;
}

double read_positive(const Json& v, const std::string& path, const Origin& o) {
  if (!is_number(v)) o.fail(path, "must be a number > 0, got " + describe(v));
  const double x = read_number(v, path, o);
  if (!(x > 0)) o.fail(path, "must be a number > 0, got " + format(x));
  return x;
}

double read_non_negative(const Json& v, const std::string& path, const Origin& o) {
  if (!is_number(v)) o.fail(path, "must be a number >= 0, got " + describe(v));
  const double x = read_number(v, path, o);
  if (!(x >= 0)) o.fail(path, "must be a number >= 0, got " + format(x));
  return x;
}

int64_t read_integer(const Json& v, const std::string& path, const Origin& o, int64_t lo, int64_t hi) {
  const std::string range = hi == std::numeric_limits<int64_t>::max()
                                ? ">= " + std::to_string(lo)
                                : "in " + std::to_string(lo) + ".." + std::to_string(hi);
  // JSON Schema counts 3.0 as an integer; so do we.
  if (!is_number(v)) o.fail(path, "must be an integer " + range + ", got " + describe(v));
  const double x = v.get<double>();
  if (!(std::isfinite(x) && x == std::floor(x))) o.fail(path, "must be an integer " + range + ", got " + describe(v));
  if (x < double(lo) || x > double(hi)) o.fail(path, "must be an integer " + range + ", got " + describe(v));
  return v.is_number_float() ? int64_t(x) : v.get<int64_t>();
}

Vec3 read_vec3(const Json& v, const std::string& path, const Origin& o) {
  if (!v.is_array() || v.size() != 3) o.fail(path, "must be an array of 3 numbers [x, y, z], got " + describe(v));
  Vec3 out;
  for (size_t i = 0; i < 3; ++i) out[int(i)] = read_number(v[i], join(path, i), o);
  return out;
}

Vec3 read_direction(const Json& v, const std::string& path, const Origin& o) {
  const Vec3 d = read_vec3(v, path, o);
  const double len = glm::length(d);
  if (!(len > 0)) o.fail(path, "must be a nonzero vector, got [0, 0, 0]");
  return d / len;
}

std::string read_string(const Json& v, const std::string& path, const Origin& o) {
  if (!v.is_string()) o.fail(path, "must be a string, got " + describe(v));
  return v.get<std::string>();
}

std::string read_name(const Json& v, const std::string& path, const Origin& o) {
  const std::string s = read_string(v, path, o);
  bool ok = !s.empty() && s.size() <= 64 && s[0] != '.' && s[0] != '-';
  for (char c : s)
    ok = ok && ((c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_' || c == '-' ||
                c == '.');
  if (!ok)
    o.fail(path,
           "must be 1 to 64 letters, digits, '_', '-' or '.', not starting with '.' or '-' (it names a "
           "folder), got " +
               describe(v));
  return s;
}

std::string read_choice(const Json& v, const std::string& path, const Origin& o,
                        std::initializer_list<std::string_view> choices) {
  if (v.is_string()) {
    const std::string s = v.get<std::string>();
    for (std::string_view c : choices)
      if (s == c) return s;
  }
  o.fail(path, "must be one of " + list(choices, "\"") + ", got " + describe(v));
}

const Json& read_array(const Json& v, const std::string& path, const Origin& o, size_t min_size) {
  if (!v.is_array()) o.fail(path, "must be an array, got " + describe(v));
  if (v.size() < min_size)
    o.fail(path, "must have at least " + std::to_string(min_size) + " entr" + (min_size == 1 ? "y" : "ies"));
  return v;
}

}  // namespace tactile::scene_json
