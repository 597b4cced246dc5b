// A minimal JSON writer for the dvm program's machine-readable output.
#pragma once

#include <cmath>
#include <cstdio>
#include <sstream>
#include <string>
#include <vector>

namespace dvm {

class Json {
 public:
  // Numbers print with 17 significant digits (round-trip exact); non-finite as null.
  static std::string number(double x) {
    if (!std::isfinite(x)) return "null";
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.17g", x);
    return buf;
  }
  static std::string string(const std::string& s) {
    std::string out = "\"";
    for (char c : s) {
      switch (c) {
        case '"': out += "\\\""; break;
        case '\\': out += "\\\\"; break;
        case '\n': out += "\\n"; break;
        case '\t': out += "\\t"; break;
        case '\r': out += "\\r"; break;
        default:
          if (static_cast<unsigned char>(c) < 0x20) {
            char buf[8];
            std::snprintf(buf, sizeof buf, "\\u%04x", c);
            out += buf;
          } else {
            out += c;
          }
      }
    }
    return out + "\"";
  }
  static std::string array(const std::vector<double>& v) {
    std::string out = "[";
    for (std::size_t i = 0; i < v.size(); ++i) out += (i ? ", " : "") + number(v[i]);
    return out + "]";
  }

  // An object built field by field, in insertion order.
  class Object {
   public:
    Object& raw(const std::string& key, const std::string& json) {
      fields_.push_back(Json::string(key) + ": " + json);
      return *this;
    }
    Object& num(const std::string& key, double x) { return raw(key, number(x)); }
    Object& str(const std::string& key, const std::string& s) { return raw(key, Json::string(s)); }
    Object& boolean(const std::string& key, bool b) { return raw(key, b ? "true" : "false"); }
    Object& arr(const std::string& key, const std::vector<double>& v) { return raw(key, array(v)); }
    std::string dump(int indent = 2) const {
      if (fields_.empty()) return "{}";
      const std::string pad(indent, ' ');
      std::string out = "{\n";
      for (std::size_t i = 0; i < fields_.size(); ++i) out += pad + fields_[i] + (i + 1 < fields_.size() ? ",\n" : "\n");
      return out + std::string(indent >= 2 ? indent - 2 : 0, ' ') + "}";
    }

   private:
    std::vector<std::string> fields_;
  };
};

}  // namespace dvm
