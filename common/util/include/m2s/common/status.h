// Errors by value for library code: Status for operations without a result, Expected<T> for
// operations with one. Messages are one clear line, meant to be shown to a user as they are.
//
//   Expected<Scene> scene = LoadScene(path, options);
//   if (!scene) { std::cerr << scene.error() << "\n"; return 1; }
#pragma once

#include <string>
#include <utility>
#include <variant>

namespace m2s {

class Status {
 public:
  Status() = default;  // OK
  static Status Ok() { return Status(); }
  static Status Error(std::string message) {
    Status s;
    s.ok_ = false;
    s.message_ = std::move(message);
    return s;
  }
  bool ok() const { return ok_; }
  explicit operator bool() const { return ok_; }
  const std::string& message() const { return message_; }

 private:
  bool ok_ = true;
  std::string message_;
};

template <typename T>
class Expected {
 public:
  Expected(T value) : data_(std::move(value)) {}       // NOLINT: implicit by design
  Expected(Status error) : data_(std::move(error)) {}  // NOLINT: must not be OK
  static Expected Error(std::string message) { return Expected(Status::Error(std::move(message))); }

  bool ok() const { return std::holds_alternative<T>(data_); }
  explicit operator bool() const { return ok(); }
  T& value() & { return std::get<T>(data_); }
  const T& value() const& { return std::get<T>(data_); }
  T&& value() && { return std::get<T>(std::move(data_)); }
  T* operator->() { return &value(); }
  const T* operator->() const { return &value(); }
  T& operator*() & { return value(); }
  const T& operator*() const& { return value(); }
  // The error message; empty when ok().
  const std::string& error() const {
    static const std::string kEmpty;
    return ok() ? kEmpty : std::get<Status>(data_).message();
  }
  Status status() const { return ok() ? Status::Ok() : std::get<Status>(data_); }

 private:
  std::variant<T, Status> data_;
};

}  // namespace m2s
