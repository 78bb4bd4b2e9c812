/* The machinery of the structs' field lists: every struct the compiled core shares with Python is one list of
 * fields, written once (structs.def), from which come its C declaration, its layout report (the field's name,
 * byte offset, numpy type and count, from which leg_env.physics.layout builds the numpy dtype) and the field's
 * documentation (the report's last entry; leg_env.physics.layout.FIELD_DOCS).
 *
 * A list is a macro of (X, S, P) whose entries are X(S, P, kind, name, dims, doc):
 *   kind  F64 (double), I32 (int32_t), FLAG (a byte, 0 or 1), or a struct of its own (PARAMS, TALLY, LOG);
 *   dims  empty for a scalar, [n] for an array;
 *   doc   what the field holds, with its unit.
 * S and P are the struct the offsets are taken in and the path to the list's struct inside it (empty, or
 * "task.hop." for a task's fields of a union), so that one list reports its fields inside another struct.
 */
#ifndef LEG_FIELDS_H
#define LEG_FIELDS_H

#include <stddef.h>
#include <stdint.h>

#include "structs.def" /* the lists: macros, expanded where robot.h and env.h declare the structs */

#define T_F64 double
#define T_I32 int32_t
#define T_FLAG uint8_t
#define T_PARAMS leg_params
#define T_TALLY leg_tally
#define T_LOG leg_log

/* a field's C declaration */
#define FIELD_DECLARE(S, P, kind, name, dims, doc) T_##kind name dims;

/* a struct field's layout entry (its own fields flattened for TALLY and LOG, a nested dtype for PARAMS) */
typedef struct {
    const char *name;
    size_t offset;
    const char *type; /* a numpy type ("f8", "i4", "?" for a byte flag) or a struct's name */
    size_t count;     /* 1 for a scalar, else the array's length */
    const char *doc;
} field_layout;

#define FIELD_ENTRY(S, P, type, name, doc, base)                                                                      \
    {#name, offsetof(S, P name), type, sizeof(((S *)0)->P name) / sizeof(base), doc},
#define FIELD_LAYOUT(S, P, kind, name, dims, doc) LAYOUT_##kind(S, P, name, doc)
#define LAYOUT_F64(S, P, name, doc) FIELD_ENTRY(S, P, "f8", name, doc, double)
#define LAYOUT_I32(S, P, name, doc) FIELD_ENTRY(S, P, "i4", name, doc, int32_t)
#define LAYOUT_FLAG(S, P, name, doc) FIELD_ENTRY(S, P, "?", name, doc, uint8_t)
#define LAYOUT_PARAMS(S, P, name, doc) FIELD_ENTRY(S, P, "leg_params", name, doc, leg_params)
#define LAYOUT_TALLY(S, P, name, doc) LEG_TALLY_FIELDS(FIELD_LEAF, S, P name.)
#define LAYOUT_LOG(S, P, name, doc) LEG_LOG_FIELDS(FIELD_LEAF, S, P name.)
/* a field of a flattened struct (its lists hold scalars and arrays only) */
#define FIELD_LEAF(S, P, kind, name, dims, doc) LEAF_##kind(S, P, name, doc)
#define LEAF_F64(S, P, name, doc) FIELD_ENTRY(S, P, "f8", name, doc, double)
#define LEAF_I32(S, P, name, doc) FIELD_ENTRY(S, P, "i4", name, doc, int32_t)

#endif
