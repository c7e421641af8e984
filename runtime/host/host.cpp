// sofac's Python host module: built once per installation (never per scene), it opens the
// generated scene libraries (plain C symbols, see runtime/sofac/abi.h) and exposes their
// instances to Python, with numpy arrays that are views of the instance's buffers.
#include <dlfcn.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

namespace py = pybind11;

namespace {

struct Library {
    using Create = void* (*)(const void* const*, const std::int64_t*);
    using Destroy = void (*)(void*);
    using BufferAt = void* (*)(void*, int, std::int64_t*);
    using Time = double* (*)(void*);
    using Step = std::int64_t (*)(void*, std::int64_t);
    using Energy = double (*)(void*, double*, double*);
    using Init = void (*)(void*);
    using UpdateMapped = void (*)(void*);

    void* handle = nullptr;
    int buffer_count = 0;
    Create create = nullptr;
    Destroy destroy = nullptr;
    BufferAt buffer = nullptr;
    Time time = nullptr;
    Step step = nullptr;
    Energy energy = nullptr;
    Init init = nullptr;
    UpdateMapped update_mapped = nullptr;

    explicit Library(const std::string& path) {
        handle = dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
        if (!handle) throw std::runtime_error(std::string("cannot open scene library: ") + dlerror());
        auto abi = reinterpret_cast<int (*)()>(symbol("sofac_abi_version"));
        if (abi() != 2) throw std::runtime_error("scene library built for another sofac ABI");
        buffer_count = reinterpret_cast<int (*)()>(symbol("sofac_buffer_count"))();
        create = reinterpret_cast<Create>(symbol("sofac_create"));
        destroy = reinterpret_cast<Destroy>(symbol("sofac_destroy"));
        buffer = reinterpret_cast<BufferAt>(symbol("sofac_buffer"));
        time = reinterpret_cast<Time>(symbol("sofac_time"));
        step = reinterpret_cast<Step>(symbol("sofac_step"));
        energy = reinterpret_cast<Energy>(symbol("sofac_energy"));
        init = reinterpret_cast<Init>(symbol("sofac_init"));
        // Only scenes whose step leaves mapped states out have it (they are mapped when read).
        update_mapped = reinterpret_cast<UpdateMapped>(dlsym(handle, "sofac_update_mapped"));
    }
    // Libraries stay loaded until the process ends: numpy views may outlive every Python handle.
    Library(const Library&) = delete;
    Library& operator=(const Library&) = delete;

    void* symbol(const char* name) {
        void* found = dlsym(handle, name);
        if (!found) throw std::runtime_error(std::string("scene library lacks ") + name);
        return found;
    }
};

struct Instance {
    std::shared_ptr<Library> library;
    void* state = nullptr;
    ~Instance() {
        if (state) library->destroy(state);
    }
};

std::shared_ptr<Instance> create(std::shared_ptr<Library> library, const py::list& arrays) {
    if (static_cast<int>(arrays.size()) != library->buffer_count)
        throw std::invalid_argument("wrong number of buffers for this scene library");
    std::vector<py::array> kept;
    std::vector<const void*> data;
    std::vector<std::int64_t> sizes;
    for (const auto& item : arrays) {
        auto array = py::reinterpret_borrow<py::array>(item);
        if (!(array.flags() & py::array::c_style)) throw std::invalid_argument("buffers must be contiguous");
        kept.push_back(array);
        data.push_back(array.data());
        sizes.push_back(static_cast<std::int64_t>(array.size()));
    }
    auto instance = std::make_shared<Instance>();
    instance->library = library;
    instance->state = library->create(data.data(), sizes.data());
    return instance;
}

// A numpy view of buffer `index`; the array keeps the instance alive.
py::array view(const std::shared_ptr<Instance>& instance, int index, bool integer) {
    std::int64_t size = 0;
    void* data = instance->library->buffer(instance->state, index, &size);
    auto owner = py::cast(instance);
    if (integer) return py::array_t<std::int64_t>({size}, {sizeof(std::int64_t)}, static_cast<std::int64_t*>(data), owner);
    return py::array_t<double>({size}, {sizeof(double)}, static_cast<double*>(data), owner);
}

}  // namespace

PYBIND11_MODULE(_sofac_host, m) {
    m.doc() = "sofac host: loads compiled scene libraries";
    py::class_<Library, std::shared_ptr<Library>>(m, "Library")
        .def(py::init<const std::string&>())
        .def_readonly("buffer_count", &Library::buffer_count);
    py::class_<Instance, std::shared_ptr<Instance>>(m, "Instance")
        .def("buffer", &view, py::arg("index"), py::arg("integer"))
        .def("step",
             [](Instance& self, std::int64_t steps) {
                 py::gil_scoped_release release;
                 return self.library->step(self.state, steps);
             })
        .def("init", [](Instance& self) { self.library->init(self.state); })
        .def("update_mapped",
             [](Instance& self) {
                 if (self.library->update_mapped) self.library->update_mapped(self.state);
             })
        .def_property(
            "time", [](Instance& self) { return *self.library->time(self.state); },
            [](Instance& self, double t) { *self.library->time(self.state) = t; })
        .def("energy", [](Instance& self) {
            double kinetic = 0.0, potential = 0.0;
            self.library->energy(self.state, &kinetic, &potential);
            return py::make_tuple(kinetic, potential);
        });
    m.def("create", &create, py::arg("library"), py::arg("buffers"));
}
