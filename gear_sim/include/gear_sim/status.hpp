// The one result shape of every fallible operation in the package (identification, wavelet
// analysis, file and bag I/O, configuration loading, the encoder front end, the segment driver):
// a Status that is ok, or carries a code, the field (option, column, parameter or key) it
// concerns when there is one, and a message in the package's one format. A value-returning
// operation returns Result<T>, a Status plus the value. Modelled on Ceres' Solver::Summary (a
// termination type plus a message) and Eigen's info() (an enum read before the value). Options
// checks keep their richer OptionStatus (options struct, field, value, rule) and convert to a
// Status without losing the field, so node parameter errors never parse message text. No ROS.
#pragma once

#include <optional>
#include <ostream>
#include <string>
#include <utility>

#include "gear_sim/option_status.hpp"

namespace gear_sim {

/// What kind of failure a Status reports.
enum class StatusCode {
  Ok,               ///< success
  InvalidArgument,  ///< an option or argument breaks a documented rule (field names it)
  InvalidInput,     ///< the data (a record, a file's content, a message) cannot be used as given
  IoError,          ///< a file or bag could not be opened, read or written
  NotIdentifiable,  ///< the data are valid but do not determine the requested quantity
  ResourceLimit,    ///< a size or memory limit would be exceeded (checked before allocating)
  Internal          ///< a numerical or logic failure inside the package
};

/// "ok", "invalid argument", ... (for logs and JSON).
inline const char* toString(StatusCode c) {
  switch (c) {
    case StatusCode::Ok:
      return "ok";
    case StatusCode::InvalidArgument:
      return "invalid argument";
    case StatusCode::InvalidInput:
      return "invalid input";
    case StatusCode::IoError:
      return "I/O error";
    case StatusCode::NotIdentifiable:
      return "not identifiable";
    case StatusCode::ResourceLimit:
      return "resource limit";
    case StatusCode::Internal:
      return "internal error";
  }
  return "unknown";
}

/// ok(), or a code, the field concerned (may be empty) and the message.
class Status {
 public:
  Status() = default;  ///< ok
  Status(StatusCode code, std::string message, std::string field = {})
      : code_(code), field_(std::move(field)), message_(std::move(message)) {
    if (code_ != StatusCode::Ok && message_.empty()) message_ = toString(code_);
  }
  /// An options check: ok stays ok; a violated rule becomes InvalidArgument with the field and
  /// OptionStatus::message() ("`Options::field = value`: violated `rule`").
  Status(const OptionStatus& s)  // NOLINT(google-explicit-constructor): one shape by design
      : Status(s.ok() ? Status() : Status(StatusCode::InvalidArgument, s.message(), s.field)) {}

  static Status invalidArgument(std::string message, std::string field = {}) {
    return {StatusCode::InvalidArgument, std::move(message), std::move(field)};
  }
  static Status invalidInput(std::string message, std::string field = {}) {
    return {StatusCode::InvalidInput, std::move(message), std::move(field)};
  }
  static Status ioError(std::string message, std::string field = {}) {
    return {StatusCode::IoError, std::move(message), std::move(field)};
  }
  static Status notIdentifiable(std::string message, std::string field = {}) {
    return {StatusCode::NotIdentifiable, std::move(message), std::move(field)};
  }
  static Status resourceLimit(std::string message, std::string field = {}) {
    return {StatusCode::ResourceLimit, std::move(message), std::move(field)};
  }
  static Status internal(std::string message, std::string field = {}) {
    return {StatusCode::Internal, std::move(message), std::move(field)};
  }

  bool ok() const { return code_ == StatusCode::Ok; }
  explicit operator bool() const { return ok(); }
  StatusCode code() const { return code_; }
  const std::string& field() const { return field_; }      ///< empty when ok or not field-specific
  const std::string& message() const { return message_; }  ///< empty when ok

  /// The same failure with `context` in front of the message ("reading 'x.csv': ..."); ok stays
  /// ok.
  Status withContext(const std::string& context) const {
    if (ok()) return *this;
    return {code_, context + ": " + message_, field_};
  }

 private:
  StatusCode code_ = StatusCode::Ok;
  std::string field_;
  std::string message_;
};

/// "ok", or "<code> [field]: message" (logs, test failure output).
inline std::ostream& operator<<(std::ostream& os, const Status& s) {
  if (s.ok()) return os << "ok";
  os << toString(s.code());
  if (!s.field().empty()) os << " [" << s.field() << "]";
  return os << ": " << s.message();
}

/// A value or the Status saying why there is none.
template <class T>
class Result {
 public:
  Result(T value) : value_(std::move(value)) {}  // NOLINT(google-explicit-constructor)
  /// A failure. An ok Status without a value is a bug in the caller: it becomes Internal.
  Result(Status status)  // NOLINT(google-explicit-constructor)
      : status_(status.ok() ? Status::internal("Result built from an ok Status without a value")
                            : std::move(status)) {}

  bool ok() const { return status_.ok() && value_.has_value(); }
  const Status& status() const { return status_; }
  const T& value() const& { return *value_; }
  T& value() & { return *value_; }
  T&& value() && { return std::move(*value_); }
  const T& operator*() const& { return *value_; }
  T& operator*() & { return *value_; }
  const T* operator->() const { return &*value_; }
  T* operator->() { return &*value_; }

 private:
  Status status_;
  std::optional<T> value_;
};

}  // namespace gear_sim
