/*
 * The layouts Python packs and the kernel reads: one definition, here.
 *
 * Each list names the float64 fields of one record, in order; the kernel reads them by
 * these names (the enums) and exports the same names to Python as _kernel.LAYOUTS
 * ({'op': (...), 'row': (...), 'link': (...)}), by which dq_fk_ros.kinematics.kernel_layout
 * packs them (test_kernel_layout.py: a field packed in the wrong place is caught).
 */
#ifndef DQ_FK_KERNEL_LAYOUT_H
#define DQ_FK_KERNEL_LAYOUT_H

/* a step of a chain's factor program (dh_code.ZStep, dh_code.XStep): kind 0 (z) or 1 (x),
 * five parameters by kind, and whether the row's frame is complete after it */
#define OP_LAYOUT(X) X(OP_KIND, "kind") X(OP_P1, "p1") X(OP_P2, "p2") X(OP_P3, "p3") \
    X(OP_P4, "p4") X(OP_P5, "p5") X(OP_MARK, "mark")

/* a DH row's TF transform (KinematicChain.row_poses): half-angle cosine and sine of alpha,
 * a, theta, d, the joint scale, the theta and d variables' indices (-1: none), alpha's
 * sine and cosine */
#define ROW_LAYOUT(X) X(ROW_COS_HALF_ALPHA, "cos_half_alpha") \
    X(ROW_SIN_HALF_ALPHA, "sin_half_alpha") X(ROW_A, "a") X(ROW_THETA, "theta") \
    X(ROW_D, "d") X(ROW_SCALE, "scale") X(ROW_THETA_INDEX, "theta_index") \
    X(ROW_D_INDEX, "d_index") X(ROW_SIN_ALPHA, "sin_alpha") X(ROW_COS_ALPHA, "cos_alpha")

/* a link of a Model (RobotModel's link plan): the frame it is fixed to and its TF parent
 * (-1: the fixed frame), its offset's 8 coefficients (w, x, y, z, w', x', y', z'), its
 * motion (-1 none, 0 revolute, 1 prismatic), the unit axis, the joint value's index in q,
 * multiplier and offset value (rad or m) */
#define LINK_LAYOUT(X) X(LINK_ATTACH, "attach") X(LINK_TF_PARENT, "tf_parent") \
    X(LINK_OFFSET, "offset_w") X(LINK_OFFSET_X, "offset_x") X(LINK_OFFSET_Y, "offset_y") \
    X(LINK_OFFSET_Z, "offset_z") X(LINK_OFFSET_DW, "offset_dw") \
    X(LINK_OFFSET_DX, "offset_dx") X(LINK_OFFSET_DY, "offset_dy") \
    X(LINK_OFFSET_DZ, "offset_dz") X(LINK_MOTION, "motion") X(LINK_AXIS, "axis_x") \
    X(LINK_AXIS_Y, "axis_y") X(LINK_AXIS_Z, "axis_z") X(LINK_Q_INDEX, "q_index") \
    X(LINK_MULTIPLIER, "multiplier") X(LINK_VALUE, "value")

#define LAYOUT_ENUM(name, text) name,
enum { OP_LAYOUT(LAYOUT_ENUM) OP_FIELDS };
enum { ROW_LAYOUT(LAYOUT_ENUM) ROW_FIELDS };
enum { LINK_LAYOUT(LAYOUT_ENUM) LINK_FIELDS };

/* joint values a chain or a model takes at most (sizes stay far from overflow) */
#define MAX_DOF (1 << 20)

#endif
