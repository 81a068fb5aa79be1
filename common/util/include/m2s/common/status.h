// Errors by value for library code: Status for operations without a result, Expected<T> for
// operations with one. Messages are one clear line, meant to be shown to a user as they are;
// code that must react to a kind of failure reads its reason code (DropReason), never the
// message.
//
//   Expected<Scene> scene = LoadScene(path, options);
//   if (!scene) { std::cerr << scene.error() << "\n"; return 1; }
//
//   Expected<FeatureFrame> frame = wire::DecodeFeatureFrame(bytes, size, limits);
//   if (!frame) ++drops[frame.reason()];
//
// An Expected built from an OK Status is a programmer error (checked).
#pragma once

#include <optional>
#include <string>
#include <utility>
#include <variant>

#include "m2s/common/check.h"
#include "m2s/common/drop_reason.h"

namespace m2s {

class [[nodiscard]] Status {
 public:
  Status() = default;  // OK
  static Status Ok() { return Status(); }
  static Status Error(std::string message) {
    Status s;
    s.ok_ = false;
    s.message_ = std::move(message);
    return s;
  }
  static Status Error(DropReason reason, std::string message) {
    Status s = Error(std::move(message));
    s.reason_ = reason;
    return s;
  }
  bool ok() const { return ok_; }
  explicit operator bool() const { return ok_; }
  const std::string& message() const { return message_; }
  // The reason code of an error that has one (decoders, validators); nullopt otherwise.
  std::optional<DropReason> reason() const { return reason_; }
  // The same error with `prefix` in front of its message ("camera: " + message).
  Status Prefixed(const std::string& prefix) const {
    Status s = *this;
    if (!ok_) s.message_ = prefix + message_;
    return s;
  }

 private:
  bool ok_ = true;
  std::string message_;
  std::optional<DropReason> reason_;
};

template <typename T>
class [[nodiscard]] Expected {
 public:
  Expected(T value) : data_(std::move(value)) {}      // NOLINT: implicit by design
  Expected(Status error) : data_(std::move(error)) {  // NOLINT: implicit by design
    M2S_CHECK(!std::get<Status>(data_).ok()) << "an Expected needs a value or an error";
  }
  static Expected Error(std::string message) { return Expected(Status::Error(std::move(message))); }
  static Expected Error(DropReason reason, std::string message) {
    return Expected(Status::Error(reason, std::move(message)));
  }

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
  // The error's reason code; only for errors that carry one (checked).
  DropReason reason() const {
    M2S_CHECK(!ok() && std::get<Status>(data_).reason()) << "reason() of a value or uncoded error";
    return *std::get<Status>(data_).reason();
  }
  Status status() const { return ok() ? Status::Ok() : std::get<Status>(data_); }

 private:
  std::variant<T, Status> data_;
};

}  // namespace m2s
