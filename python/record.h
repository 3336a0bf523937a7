// Typed results of the module (docs/python.md, "Results"): a C++ struct bound as a Python class
// whose fields are read-only attributes, with to_dict() (the field names as keys, in order; a
// nested result as a dict), == (every field the same: NaN equal to NaN, arrays by shape and
// entries), a repr naming every field (arrays by their shape) and pickle (the state is
// to_dict()). Arrays read as attributes are read-only views into the object; to_dict() copies.
#pragma once

#include <cmath>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <pybind11/eigen.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include "conversions.h"

namespace arbor::python {

/// Whether a and b hold the same value: NaN is the same as NaN, matrices by shape and entries.
inline bool sameValue(double a, double b) { return a == b || (std::isnan(a) && std::isnan(b)); }
inline bool sameValue(const RowMatrix& a, const RowMatrix& b) {
  if (a.rows() != b.rows() || a.cols() != b.cols()) return false;
  for (Eigen::Index k = 0; k < a.size(); ++k)
    if (!sameValue(a.data()[k], b.data()[k])) return false;
  return true;
}
template <class T>
bool sameValue(const T& a, const T& b) {
  return a == b;
}
template <class T>
bool sameValue(const std::optional<T>& a, const std::optional<T>& b) {
  return a.has_value() == b.has_value() && (!a || sameValue(*a, *b));
}

/// One field of a record: its attribute (`owner` keeps an array view's object alive), its plain
/// value for to_dict(), its setter from that plain value (pickle), and its comparison.
template <class T>
struct RecordField {
  std::string name, doc;
  std::function<py::object(const T&, py::handle owner)> get;
  std::function<py::object(const T&)> plain;
  std::function<void(T&, const py::handle&)> set;
  std::function<bool(const T&, const T&)> same;
};

/// Binds T as the Python class `name` of m; each field() adds a read-only attribute.
template <class T>
class Record {
 public:
  Record(py::module_& m, const char* name, const char* doc)
      : cls_(m, name, doc), fields_(std::make_shared<std::vector<RecordField<T>>>()) {
    const auto fields = fields_;
    const std::string type = name;
    cls_.def(
        "to_dict", [fields](const T& t) { return toDict(*fields, t); },
        "The fields as a dict (arrays copied, a nested result as a dict).");
    cls_.def(
        "__eq__",
        [fields](const T& a, const py::object& b) -> py::object {
          if (!py::isinstance<T>(b)) return py::reinterpret_borrow<py::object>(Py_NotImplemented);
          return py::bool_(same(*fields, a, b.cast<const T&>()));
        },
        py::is_operator(), "Every field the same (NaN equal to NaN, arrays by shape and entries).");
    cls_.def(
        "__repr__",
        [fields, type](const py::object& self) {
          const T& t = self.cast<const T&>();
          std::string out = type + "(";
          for (size_t k = 0; k < fields->size(); ++k) {
            const RecordField<T>& f = (*fields)[k];
            const py::object value = f.get(t, self);
            out += (k ? ", " : "") + f.name + "=";
            if (py::isinstance<py::array>(value)) {
              std::string shape;
              for (const py::handle& n : value.attr("shape").cast<py::tuple>())
                shape += (shape.empty() ? "" : "x") + std::string(py::str(n));
              out += "<array " + shape + ">";
            } else {
              out += py::repr(value);
            }
          }
          return out + ")";
        },
        "Every field by name, arrays by their shape.");
    cls_.def(py::pickle([fields](const T& t) { return toDict(*fields, t); },
                        [fields, type](const py::dict& d) { return fromDict(*fields, type, d); }));
  }

  /// A field held by the member `member`; a std::vector<Key> reads as an int64 array.
  template <class M>
  Record& field(const char* name, M T::*member, const char* doc) {
    RecordField<T> f;
    f.name = name;
    f.doc = doc;
    f.plain = [member](const T& t) { return plainOf(t.*member); };
    if constexpr (std::is_same_v<M, RowMatrix>)
      f.get = [member](const T& t, py::handle owner) {
        return py::cast(t.*member, py::return_value_policy::reference_internal, owner);
      };
    else
      f.get = [member](const T& t, py::handle) { return plainOf(t.*member); };
    f.set = [member](T& t, const py::handle& v) { t.*member = v.cast<M>(); };
    f.same = [member](const T& a, const T& b) { return sameValue(a.*member, b.*member); };
    return add(std::move(f));
  }

  /// A field that is itself a record (bound before as `record`): an attribute of that class,
  /// a dict in to_dict().
  template <class M>
  Record& nested(const char* name, M T::*member, const Record<M>& record, const char* doc) {
    const auto inner = record.fields_;
    RecordField<T> f;
    f.name = name;
    f.doc = doc;
    f.get = [member](const T& t, py::handle) { return py::cast(t.*member); };
    f.plain = [member, inner](const T& t) -> py::object {
      return Record<M>::toDict(*inner, t.*member);
    };
    const std::string type = std::string(py::str(record.cls_.attr("__name__")));
    f.set = [member, inner, type](T& t, const py::handle& v) {
      t.*member = Record<M>::fromDict(*inner, type, v.cast<py::dict>());
    };
    f.same = [member, inner](const T& a, const T& b) {
      return Record<M>::same(*inner, a.*member, b.*member);
    };
    return add(std::move(f));
  }

 private:
  template <class>
  friend class Record;

  Record& add(RecordField<T> f) {
    const auto get = f.get;
    cls_.def_property_readonly(
        f.name.c_str(), [get](const py::object& self) { return get(self.cast<const T&>(), self); },
        f.doc.c_str());
    fields_->push_back(std::move(f));
    return *this;
  }

  template <class M>
  static py::object plainOf(const M& value) {
    if constexpr (std::is_same_v<M, std::vector<Key>>)
      return idsToArray(value);
    else
      return py::cast(value);
  }

  static py::dict toDict(const std::vector<RecordField<T>>& fields, const T& t) {
    py::dict d;
    for (const RecordField<T>& f : fields) d[f.name.c_str()] = f.plain(t);
    return d;
  }

  static T fromDict(const std::vector<RecordField<T>>& fields, const std::string& type,
                    const py::dict& d) {
    T t;
    for (const RecordField<T>& f : fields) {
      if (!d.contains(f.name))
        throw std::invalid_argument(type + " state: no field '" + f.name + "'");
      try {
        f.set(t, d[f.name.c_str()]);
      } catch (const py::cast_error&) {
        throw py::type_error(type + " state: field '" + f.name + "' has the wrong type (" +
                             std::string(py::str(d[f.name.c_str()].get_type())) + ")");
      }
    }
    if (d.size() != fields.size())
      for (const auto& [key, value] : d) {
        bool known = false;
        for (const RecordField<T>& f : fields) known = known || f.name == std::string(py::str(key));
        if (!known)
          throw std::invalid_argument(type + " state: unknown field '" + std::string(py::str(key)) +
                                      "'");
      }
    return t;
  }

  static bool same(const std::vector<RecordField<T>>& fields, const T& a, const T& b) {
    for (const RecordField<T>& f : fields)
      if (!f.same(a, b)) return false;
    return true;
  }

  py::class_<T> cls_;
  std::shared_ptr<std::vector<RecordField<T>>> fields_;
};

}  // namespace arbor::python
