/*
 * Serialized messages published through rcl, many publishers in one call (dq_fk_node).
 *
 * rclpy's Publisher.publish_raw costs ~0.75 us a message here, of which rcl and Fast DDS
 * take ~0.36 (benchmarks/bench_node.py prints both); a tiago_dual update publishes 130
 * messages. Publishers(handles) holds rclpy's own publisher handles (the exact type
 * rclpy._rclpy_pybind11.Publisher, nothing else) entered as rclpy's `with handle:` does, so
 * a publisher destroyed meanwhile (Node.destroy_publisher) is only destroyed once close()
 * (or the object's end) lets go of it: the rcl_publisher_t read from a handle at the start
 * stays alive while it is held. publish(messages) hands message i (bytes) to publisher i
 * with rcl_publish_serialized_message, the call publish_raw makes, GIL held throughout.
 * The reference is publish_raw itself: test/integration/test_publisher_group.py holds the
 * two equal (a subscriber receives the same bytes from both).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>

#include <rcl/error_handling.h>
#include <rcl/publisher.h>

#define MAX_PUBLISHERS (1 << 20)

typedef struct {
    PyObject_HEAD
    Py_ssize_t n;
    PyObject **handles;                  /* entered rclpy handles (owned references) */
    const rcl_publisher_t **publishers;  /* each handle's rcl publisher, alive while held */
    int closed;
} Publishers;

static PyObject *publisher_type;  /* rclpy._rclpy_pybind11.Publisher, looked up once */

/* rclpy's publisher handle type, imported the first time it is needed. */
static PyObject *rclpy_publisher_type(void)
{
    if (publisher_type == NULL) {
        PyObject *module = PyImport_ImportModule("rclpy._rclpy_pybind11");
        if (module == NULL)
            return NULL;
        PyObject *type = PyObject_GetAttrString(module, "Publisher");
        Py_DECREF(module);
        if (type == NULL)
            return NULL;
        if (!PyType_Check(type)) {
            Py_DECREF(type);
            PyErr_SetString(PyExc_TypeError, "rclpy._rclpy_pybind11.Publisher is not a type");
            return NULL;
        }
        publisher_type = type;
    }
    return publisher_type;
}

/* Let go of the first n handles (rclpy's handle.__exit__); the first error is kept. */
static int release_handles(PyObject **handles, Py_ssize_t n)
{
    int failed = 0;
    for (Py_ssize_t i = 0; i < n; i++) {
        PyObject *out = PyObject_CallMethod(handles[i], "__exit__", "OOO", Py_None, Py_None,
                                            Py_None);
        if (out == NULL) {
            if (failed)
                PyErr_Clear();
            failed = 1;
        } else {
            Py_DECREF(out);
        }
        Py_DECREF(handles[i]);
    }
    return failed ? -1 : 0;
}

static void publishers_clear(Publishers *self, int report)
{
    PyObject **handles = self->handles;
    Py_ssize_t n = self->n;
    self->handles = NULL;
    self->n = 0;
    self->closed = 1;
    PyMem_Free(self->publishers);
    self->publishers = NULL;
    if (handles == NULL)
        return;
    if (release_handles(handles, n) < 0 && !report)
        PyErr_WriteUnraisable(NULL);
    PyMem_Free(handles);
}

static PyObject *publishers_new(PyTypeObject *type, PyObject *args, PyObject *kwargs)
{
    static char *keywords[] = {"handles", NULL};
    PyObject *given;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "O:Publishers", keywords, &given))
        return NULL;
    PyObject *handle_type = rclpy_publisher_type();
    if (handle_type == NULL)
        return NULL;
    PyObject *seq = PySequence_Tuple(given);  /* our own copy: nothing can change it */
    if (seq == NULL) {
        PyErr_Clear();
        PyErr_SetString(PyExc_TypeError, "Publishers: handles must be a sequence of rclpy "
                        "publisher handles (Publisher.handle)");
        return NULL;
    }
    Py_ssize_t n = PyTuple_GET_SIZE(seq);
    if (n > MAX_PUBLISHERS) {
        Py_DECREF(seq);
        return PyErr_Format(PyExc_ValueError, "Publishers: at most %d handles, not %zd",
                            MAX_PUBLISHERS, n);
    }
    for (Py_ssize_t i = 0; i < n; i++)
        if (Py_TYPE(PyTuple_GET_ITEM(seq, i)) != (PyTypeObject *)handle_type) {
            PyErr_Format(PyExc_TypeError, "Publishers: handle %zd is a %.100s, not an rclpy "
                         "publisher handle (Publisher.handle)", i,
                         Py_TYPE(PyTuple_GET_ITEM(seq, i))->tp_name);
            Py_DECREF(seq);  /* after the message: the item's type name lives in it */
            return NULL;
        }
    Publishers *self = (Publishers *)type->tp_alloc(type, 0);
    if (self == NULL) {
        Py_DECREF(seq);
        return NULL;
    }
    PyObject **handles = PyMem_New(PyObject *, n ? n : 1);
    const rcl_publisher_t **publishers = PyMem_New(const rcl_publisher_t *, n ? n : 1);
    if (handles == NULL || publishers == NULL) {
        PyMem_Free(handles);
        PyMem_Free(publishers);
        Py_DECREF(seq);
        Py_DECREF(self);
        return PyErr_NoMemory();
    }
    Py_ssize_t entered = 0;
    for (; entered < n; entered++) {
        PyObject *handle = PyTuple_GET_ITEM(seq, entered);
        /* held first: a handle whose destruction was asked for refuses (InvalidHandle) */
        PyObject *out = PyObject_CallMethod(handle, "__enter__", NULL);
        if (out == NULL)
            break;
        Py_DECREF(out);
        Py_INCREF(handle);
        handles[entered] = handle;
        PyObject *address = PyObject_GetAttrString(handle, "pointer");
        void *pointer = address == NULL ? NULL : PyLong_AsVoidPtr(address);
        Py_XDECREF(address);
        if (pointer == NULL || !rcl_publisher_is_valid((const rcl_publisher_t *)pointer)) {
            rcl_reset_error();
            if (!PyErr_Occurred())
                PyErr_Format(PyExc_ValueError, "Publishers: handle %zd is not a valid "
                             "publisher (destroyed, or its context shut down)", entered);
            entered++;
            break;
        }
        publishers[entered] = (const rcl_publisher_t *)pointer;
    }
    Py_DECREF(seq);
    if (PyErr_Occurred()) {
        PyObject *type_, *value, *traceback;
        PyErr_Fetch(&type_, &value, &traceback);
        if (release_handles(handles, entered) < 0)
            PyErr_Clear();
        PyErr_Restore(type_, value, traceback);
        PyMem_Free(handles);
        PyMem_Free(publishers);
        Py_DECREF(self);
        return NULL;
    }
    self->n = n;
    self->handles = handles;
    self->publishers = publishers;
    return (PyObject *)self;
}

static void publishers_dealloc(Publishers *self)
{
    publishers_clear(self, 0);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

static PyObject *publishers_publish(Publishers *self, PyObject *messages)
{
    if (self->closed) {
        PyErr_SetString(PyExc_ValueError, "Publishers.publish: closed");
        return NULL;
    }
    if (!PyList_CheckExact(messages) && !PyTuple_CheckExact(messages))
        return PyErr_Format(PyExc_TypeError, "Publishers.publish: a list or tuple of bytes, "
                            "not %.100s", Py_TYPE(messages)->tp_name);
    Py_ssize_t n = PySequence_Fast_GET_SIZE(messages);
    if (n != self->n)
        return PyErr_Format(PyExc_ValueError, "Publishers.publish: %zd messages for %zd "
                            "publishers", n, self->n);
    PyObject **items = PySequence_Fast_ITEMS(messages);
    for (Py_ssize_t i = 0; i < n; i++)
        if (!PyBytes_Check(items[i]))
            return PyErr_Format(PyExc_TypeError, "Publishers.publish: message %zd is a "
                                "%.100s, not bytes", i, Py_TYPE(items[i])->tp_name);
    /* no Python code runs below: the list cannot change under us (the GIL is held) */
    for (Py_ssize_t i = 0; i < n; i++) {
        rcl_serialized_message_t message = rmw_get_zero_initialized_serialized_message();
        message.buffer = (uint8_t *)PyBytes_AS_STRING(items[i]);
        message.buffer_length = (size_t)PyBytes_GET_SIZE(items[i]);
        message.buffer_capacity = message.buffer_length;
        if (rcl_publish_serialized_message(self->publishers[i], &message, NULL) !=
                RCL_RET_OK) {
            PyErr_Format(PyExc_RuntimeError, "Publishers.publish: message %zd: %s", i,
                         rcl_get_error_string().str);
            rcl_reset_error();
            return NULL;
        }
    }
    Py_RETURN_NONE;
}

static PyObject *publishers_close(Publishers *self, PyObject *unused)
{
    (void)unused;
    publishers_clear(self, 1);
    if (PyErr_Occurred())
        return NULL;
    Py_RETURN_NONE;
}

static Py_ssize_t publishers_length(Publishers *self)
{
    return self->n;
}

static PyMethodDef publishers_methods[] = {
    {"publish", (PyCFunction)publishers_publish, METH_O,
     "publish(messages): message i (bytes) on publisher i, through rcl; a list or tuple as "
     "long as the publishers."},
    {"close", (PyCFunction)publishers_close, METH_NOARGS,
     "close(): let go of the handles (a publisher destroyed meanwhile is destroyed now); "
     "publish then refuses. Idempotent."},
    {NULL, NULL, 0, NULL},
};

static PySequenceMethods publishers_as_sequence = {
    .sq_length = (lenfunc)publishers_length,
};

static PyTypeObject PublishersType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "dq_fk_ros.ros._rcl_publish.Publishers",
    .tp_doc = "Publishers(handles): rclpy publisher handles, held; publish(messages) sends "
              "serialized messages through rcl.",
    .tp_basicsize = sizeof(Publishers),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_new = publishers_new,
    .tp_dealloc = (destructor)publishers_dealloc,
    .tp_methods = publishers_methods,
    .tp_as_sequence = &publishers_as_sequence,
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_rcl_publish",
    "Serialized messages through rcl, many publishers a call (dq_fk_node's fast path).", -1,
    NULL,
};

PyMODINIT_FUNC PyInit__rcl_publish(void)
{
    if (PyType_Ready(&PublishersType) < 0)
        return NULL;
    PyObject *m = PyModule_Create(&module);
    if (m == NULL)
        return NULL;
    Py_INCREF(&PublishersType);
    if (PyModule_AddObject(m, "Publishers", (PyObject *)&PublishersType) < 0) {
        Py_DECREF(&PublishersType);
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
