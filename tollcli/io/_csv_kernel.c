/* The compiled twin of the CSV writer's rows (tollcli/io/csv_rows.py): a chunk of columns → the CSV text of its
 * rows, byte for byte what Python's csv module writes for the cells io.writers._csv_cells makes (floats as
 * "%.15g", NaN empty, integers in decimal, booleans True/False, other cells given already made).
 *
 * Floats: Python formats "%.15g" by correct rounding of the exact binary value (round half to even on an exact
 * tie), as glibc's printf does; both cost ~0.5 us a value. Here, for values printed without an exponent
 * (1e-4 <= |v| < 1e15), the 15 significant digits come from one product with an exact power of ten and its exact
 * error (fma), which decides the rounding exactly; an exact tie and every other value go to snprintf.
 * tests/test_csv_rows.py holds the two to Python's own formatting on random and edge values.
 *
 * No numpy headers: only the buffer protocol.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

static const double POW10[19] = {1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9,
                                 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16, 1e17, 1e18};

/* N = the exact a * 10^k rounded to the nearest integer; 0 on an exact tie (the caller then asks printf).
 * a > 0, 0 <= k <= 18, a * 10^k < 2^52. */
static int round_scaled(double a, int k, int64_t *n) { /* built with -ffp-contract=off: no product fused but fma's */
    double s = POW10[k];
    double p = a * s;
    double r = fma(a, s, -p); /* a * s = p + r exactly */
    double fl = floor(p);
    double f = p - fl;        /* exact: p < 2^52 */
    /* round(p + r): compare f + r with 1/2 exactly: f - 0.5 is exact where it matters (f >= 1/4; |r| <= 1/8) */
    double d = f - 0.5;
    if (d > -r) {
        *n = (int64_t)fl + 1;
    } else if (d < -r) {
        *n = (int64_t)fl;
    } else {
        return 0;
    }
    return 1; /* |r| <= ulp(p) / 2 <= 1/4: p + r never passes below fl or above fl + 1 in a way not decided here */
}

/* "%.15g" of v (finite, not zero) into out; its length. */
static int format_g15(double v, char *out) {
    double a = fabs(v);
    if (a >= 1e-4 && a < 1e15) {
        int e = (int)floor(log10(a));
        if (e < -4) e = -4;
        if (e > 14) e = 14;
        const int64_t P14 = 100000000000000LL, P15 = 1000000000000000LL;
        int64_t n = 0, m = 0;
        int ok = round_scaled(a, 14 - e, &n);
        if (ok && n >= P15) { /* the exponent was one too low */
            e++;
            ok = e <= 14 && round_scaled(a, 14 - e, &n);
        } else if (ok && n < P14) { /* one too high */
            e--;
            ok = e >= -4 && round_scaled(a, 14 - e, &n);
        }
        ok = ok && n >= P14 && n < P15;
        /* 10^14 at e may be a value below 10^e rounded up: its 15 digits are those one exponent down, unless
         * they round up to 10^15 there too */
        if (ok && n == P14) {
            if (e - 1 < -4 || !round_scaled(a, 15 - e, &m)) ok = 0;
            else if (m >= P14 && m < P15) { e--; n = m; }
        }
        if (ok && e >= -4 && e <= 14) {
            char digits[16];
            for (int i = 14; i >= 0; i--) { digits[i] = (char)('0' + n % 10); n /= 10; }
            int last = 14; /* the last significant digit kept after trailing zeros go */
            while (last > 0 && digits[last] == '0') last--;
            char *o = out;
            if (v < 0) *o++ = '-';
            if (e >= 0) {
                memcpy(o, digits, (size_t)e + 1);
                o += e + 1;
                if (last > e) {
                    *o++ = '.';
                    memcpy(o, digits + e + 1, (size_t)(last - e));
                    o += last - e;
                }
            } else {
                *o++ = '0';
                *o++ = '.';
                for (int z = 0; z < -e - 1; z++) *o++ = '0';
                memcpy(o, digits, (size_t)last + 1);
                o += last + 1;
            }
            return (int)(o - out);
        }
    }
    return snprintf(out, 32, "%.15g", v);
}

static int format_float_cell(double v, char *out) {
    if (v != v) return 0; /* NaN: an empty cell */
    if (isinf(v)) {
        if (v < 0) { memcpy(out, "-inf", 4); return 4; }
        memcpy(out, "inf", 3);
        return 3;
    }
    if (v == 0) {
        if (signbit(v)) { memcpy(out, "-0", 2); return 2; }
        out[0] = '0';
        return 1;
    }
    return format_g15(v, out);
}

static int format_int(int64_t v, char *out) {
    char tmp[24];
    int len = 0;
    uint64_t u = v < 0 ? (uint64_t)0 - (uint64_t)v : (uint64_t)v;
    do { tmp[len++] = (char)('0' + u % 10); u /= 10; } while (u);
    int o = 0;
    if (v < 0) out[o++] = '-';
    while (len) out[o++] = tmp[--len];
    return o;
}

enum { KIND_FLOAT = 'f', KIND_INT = 'i', KIND_BOOL = 'b', KIND_CELLS = 'c' };

typedef struct {
    int kind;
    Py_buffer values;  /* f: float64, i: int64, b: uint8, c: the cells' bytes */
    Py_buffer offsets; /* c: int64, n + 1 */
    int has_values, has_offsets;
} Column;

/* rows(kinds, columns, n) → bytes
 *
 * kinds: bytes, one of b"fibc" per column; columns: a tuple, per column its array (f, i, b) or a tuple
 * (cells' bytes, int64 offsets of n + 1) for c. The rows, comma-separated, each ended by "\n".
 */
static PyObject *rows(PyObject *self, PyObject *args) {
    const char *kinds;
    Py_ssize_t n_kinds, n;
    PyObject *cols;
    if (!PyArg_ParseTuple(args, "y#O!n", &kinds, &n_kinds, &PyTuple_Type, &cols, &n)) return NULL;
    if (PyTuple_GET_SIZE(cols) != n_kinds || n < 0) {
        PyErr_SetString(PyExc_ValueError, "rows: one kind per column");
        return NULL;
    }
    Column *c = PyMem_Calloc((size_t)(n_kinds ? n_kinds : 1), sizeof(Column));
    if (!c) return PyErr_NoMemory();
    PyObject *result = NULL;
    char *out = NULL;
    Py_ssize_t width = 0, cell_bytes = 0;
    for (Py_ssize_t j = 0; j < n_kinds; j++) {
        PyObject *item = PyTuple_GET_ITEM(cols, j), *values = item, *offsets = NULL;
        int kind = c[j].kind = kinds[j];
        if (kind != KIND_FLOAT && kind != KIND_INT && kind != KIND_BOOL && kind != KIND_CELLS) {
            PyErr_SetString(PyExc_ValueError, "rows: a kind is one of f, i, b, c");
            goto done;
        }
        if (kind == KIND_CELLS && !PyArg_ParseTuple(item, "OO", &values, &offsets)) goto done;
        if (PyObject_GetBuffer(values, &c[j].values, PyBUF_SIMPLE) < 0) goto done;
        c[j].has_values = 1;
        if (kind == KIND_CELLS) {
            if (PyObject_GetBuffer(offsets, &c[j].offsets, PyBUF_SIMPLE) < 0) goto done;
            c[j].has_offsets = 1;
            if (c[j].offsets.len < (n + 1) * 8) { PyErr_SetString(PyExc_ValueError, "rows: offsets too short"); goto done; }
            const int64_t *off = c[j].offsets.buf;
            if (off[0] < 0 || off[n] > c[j].values.len) { PyErr_SetString(PyExc_ValueError, "rows: offsets out of the cells"); goto done; }
            for (Py_ssize_t i = 0; i < n; i++)
                if (off[i + 1] < off[i]) { PyErr_SetString(PyExc_ValueError, "rows: offsets not sorted"); goto done; }
            cell_bytes += off[n] - off[0];
        } else {
            if (c[j].values.len < n * (kind == KIND_BOOL ? 1 : 8)) { PyErr_SetString(PyExc_ValueError, "rows: a column is too short"); goto done; }
            width += kind == KIND_BOOL ? 5 : 32;
        }
    }
    out = PyMem_Malloc((size_t)(n * (width + n_kinds + 1) + cell_bytes + 1));
    if (!out) { PyErr_NoMemory(); goto done; }
    char *o = out;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < n; i++) {
        for (Py_ssize_t j = 0; j < n_kinds; j++) {
            if (j) *o++ = ',';
            switch (c[j].kind) {
            case KIND_FLOAT: o += format_float_cell(((const double *)c[j].values.buf)[i], o); break;
            case KIND_INT: o += format_int(((const int64_t *)c[j].values.buf)[i], o); break;
            case KIND_BOOL:
                if (((const uint8_t *)c[j].values.buf)[i]) { memcpy(o, "True", 4); o += 4; }
                else { memcpy(o, "False", 5); o += 5; }
                break;
            default: {
                const int64_t *off = c[j].offsets.buf;
                size_t len = (size_t)(off[i + 1] - off[i]);
                memcpy(o, (const char *)c[j].values.buf + off[i], len);
                o += len;
            }
            }
        }
        *o++ = '\n';
    }
    Py_END_ALLOW_THREADS
    result = PyBytes_FromStringAndSize(out, o - out);
done:
    for (Py_ssize_t j = 0; j < n_kinds; j++) {
        if (c[j].has_values) PyBuffer_Release(&c[j].values);
        if (c[j].has_offsets) PyBuffer_Release(&c[j].offsets);
    }
    PyMem_Free(c);
    PyMem_Free(out);
    return result;
}

static PyObject *float_cell(PyObject *self, PyObject *arg) {
    double v = PyFloat_AsDouble(arg);
    if (v == -1.0 && PyErr_Occurred()) return NULL;
    char buf[40];
    int len = format_float_cell(v, buf);
    return PyUnicode_FromStringAndSize(buf, len);
}

static PyMethodDef methods[] = {
    {"rows", rows, METH_VARARGS, "A chunk's CSV rows (see tollcli.io.csv_rows.csv_text)."},
    {"float_cell", float_cell, METH_O, "One float's cell: '%.15g' % v, '' for NaN (for the tests)."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_csv_kernel",
                                    "The compiled twin of the CSV writer's rows.", -1, methods};

PyMODINIT_FUNC PyInit__csv_kernel(void) { return PyModule_Create(&module); }
