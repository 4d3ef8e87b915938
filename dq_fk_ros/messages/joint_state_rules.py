"""
The input rules of a JointState, as constants: what may happen to a message, and why.

Shared by the merge's three forms (``joint_states.JointStateMerger.merge``, the compiled
short path ``joint_state_raw`` and the arrays of ``joint_state_batches``).
"""

OUT_OF_LIMITS_POLICIES = ('warn', 'clamp', 'reject')
# A stamp this far before the last accepted one is a time jump (a looping bag, a restarted
# simulation): the merger resets. Smaller steps back are out-of-order messages and merge.
TIME_JUMP_BACK_NS = 1_000_000_000
# Unknown joint names are remembered (and reported) up to this many; later new names are
# only counted (counts['unknown_names_unlisted']), so a flood of made-up names cannot grow
# memory, logs or /diagnostics.
MAX_UNKNOWN_LISTED = 20

# Outcomes of a message, as counted in MergeResult.status / JointStateMerger.counts
PUBLISH = 'publish'          # complete joint vector, to be published
INCOMPLETE = 'incomplete'    # valid, but some joints were never seen yet
REJECTED = 'rejected'        # malformed or refused; nothing of it was kept

REJECT_REASONS = {
    'empty': 'the message names no joints',
    'length_mismatch': 'name, position and velocity arrays differ in length',
    'duplicate_name': 'a joint is named twice',
    'non_finite': 'a position is NaN or infinite',
    'no_known_joint': 'none of its joints belong to this robot',
    'out_of_limits': 'a joint is outside its limits (out_of_limits: reject)',
}
