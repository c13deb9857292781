// Plain values as bytes and back, exactly: what a sweep's result slot becomes to travel between
// the processes of an MPI job (SweepEngine, ItemCodec). Numbers are copied byte for byte (a
// double comes back bit for bit, NaN payloads included); strings carry their length. Both ends
// are the same program on the same kind of machine, so there is no byte-order conversion.
#pragma once

#include <cstddef>
#include <cstring>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <type_traits>

namespace flatland::sim {

class ByteWriter {
 public:
  explicit ByteWriter(std::string& out) : out_(out) {}
  template <class T>
  requires std::is_trivially_copyable_v<T>
  void put(const T& value) { out_.append(reinterpret_cast<const char*>(&value), sizeof value); }
  void put(const std::string& s) {
    put(s.size());
    out_.append(s);
  }
  template <class T>
  void put(const std::optional<T>& value) {
    put(value.has_value());
    if (value) put(*value);
  }

 private:
  std::string& out_;
};

class ByteReader {
 public:
  explicit ByteReader(std::string_view in) : in_(in) {}
  template <class T>
  requires std::is_trivially_copyable_v<T>
  void get(T& value) { std::memcpy(&value, take(sizeof value), sizeof value); }
  void get(std::string& s) {
    std::size_t n = 0;
    get(n);
    const char* p = take(n);
    s.assign(p, n);
  }
  template <class T>
  void get(std::optional<T>& value) {
    bool has = false;
    get(has);
    if (!has) {
      value.reset();
      return;
    }
    T v{};
    get(v);
    value = std::move(v);
  }
  /// True when every byte was read (a slot that leaves bytes over was packed differently).
  bool at_end() const { return pos_ == in_.size(); }

 private:
  const char* take(std::size_t n) {
    if (n > in_.size() - pos_)
      throw std::runtime_error("item bytes: a result slot ends early (" +
                               std::to_string(in_.size() - pos_) + " bytes left, " +
                               std::to_string(n) + " wanted)");
    const char* p = in_.data() + pos_;
    pos_ += n;
    return p;
  }
  std::string_view in_;
  std::size_t pos_ = 0;
};

}  // namespace flatland::sim
