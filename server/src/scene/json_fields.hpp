// Strict reading of JSON values for the scene loader: every error names the
// file, the JSON path of the value at fault (`boundary[0].select.box.lo`) and
// what was expected, and an object may hold only the fields it declares.
#pragma once

#include <cstdint>
#include <initializer_list>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/mesh.hpp"
#include "scene/scene.hpp"

namespace tactile::scene_json {

using Json = nlohmann::json;

// Where values come from, for messages: the file and, while a variant is
// being read, its name.
struct Origin {
  std::string file;
  std::string variant;

  // "file: variant 'v': path: what" (path and variant omitted when empty).
  [[noreturn]] void fail(const std::string& path, const std::string& what) const;
};

// `path.key`, or `key` at the root.
std::string join(const std::string& path, std::string_view key);
// `path[i]`.
std::string join(const std::string& path, size_t i);

// A short rendering of a JSON value for messages: `-1`, `"fast"`, `an object`.
std::string describe(const Json& v);

// A JSON object whose fields are all known in advance: constructing it
// refuses a non-object and any field not in `allowed`, naming it.
class Fields {
 public:
  Fields(const Json& j, std::string path, const Origin& origin, std::initializer_list<std::string_view> allowed);

  bool has(std::string_view key) const { return j_.contains(key); }
  // The field, or a "required field missing" error.
  const Json& at(std::string_view key) const;
  // The field, or nullptr when absent.
  const Json* find(std::string_view key) const;
  std::string path(std::string_view key) const { return join(path_, key); }
  const std::string& path() const { return path_; }
  const Origin& origin() const { return origin_; }

  // Typed readers of a required field, with the same checks as the free
  // functions below.
  double number(std::string_view key) const;
  double positive(std::string_view key) const;
  double non_negative(std::string_view key) const;
  int64_t integer(std::string_view key, int64_t lo, int64_t hi) const;
  Vec3 vec3(std::string_view key) const;
  std::string string(std::string_view key) const;

  // Optional variants: the default when the field is absent.
  double number_or(std::string_view key, double fallback) const;
  double positive_or(std::string_view key, double fallback) const;
  double non_negative_or(std::string_view key, double fallback) const;
  int64_t integer_or(std::string_view key, int64_t lo, int64_t hi, int64_t fallback) const;
  std::string string_or(std::string_view key, const std::string& fallback) const;

 private:
  const Json& j_;
  std::string path_;
  const Origin& origin_;
};

// Readers of one value at `path`; each refuses other types and non-finite numbers.
double read_number(const Json& v, const std::string& path, const Origin& o);
double read_positive(const Json& v, const std::string& path, const Origin& o);      // > 0
double read_non_negative(const Json& v, const std::string& path, const Origin& o);  // >= 0
int64_t read_integer(const Json& v, const std::string& path, const Origin& o, int64_t lo, int64_t hi);
Vec3 read_vec3(const Json& v, const std::string& path, const Origin& o);
Vec3 read_direction(const Json& v, const std::string& path, const Origin& o);  // nonzero, normalised
std::string read_string(const Json& v, const std::string& path, const Origin& o);
// A name usable as a folder: letters, digits, '_', '-', '.', not starting with '.' or '-'.
std::string read_name(const Json& v, const std::string& path, const Origin& o);
// One of `choices`, else an error listing them.
std::string read_choice(const Json& v, const std::string& path, const Origin& o,
                        std::initializer_list<std::string_view> choices);
// The array at path, else an error; empty arrays are allowed when `min_size` is 0.
const Json& read_array(const Json& v, const std::string& path, const Origin& o, size_t min_size);

}  // namespace tactile::scene_json
