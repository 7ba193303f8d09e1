#pragma once
// Raw binary fields for the caches that teachsim writes and reads back on the same machine (the
// recognizer's model-view index, the LINE-MOD peer's templates): native byte order, trivially
// copyable values only; the files carry a magic tag and a key so that a foreign or stale file is
// rebuilt, never trusted.

#include <istream>
#include <string>
#include <type_traits>

namespace teachsim::binary {

template <typename T>
void Put(std::string* out, const T& value) {
  static_assert(std::is_trivially_copyable_v<T>);
  out->append(reinterpret_cast<const char*>(&value), sizeof(T));
}

// False when the stream ends before the value is complete.
template <typename T>
[[nodiscard]] bool Get(std::istream& in, T* value) {
  static_assert(std::is_trivially_copyable_v<T>);
  return static_cast<bool>(in.read(reinterpret_cast<char*>(value), sizeof(T)));
}

}  // namespace teachsim::binary
