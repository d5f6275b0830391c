"""The fuzzy exploration controller of the paper (section 5), in integers (docs/fuzzy.md).

A zero-order Sugeno engine over the eight reflected IR readings: each rule's firing
strength (0..1024) weights a pair of wheel-speed singletons, and the setpoints are the
weighted averages, rounded half up.  No floating point, so every port computes the same
setpoints bit for bit.  The rule bases are data (RULES_FIRST, RULES_REFINED);
host_sim/controller/fuzzy_rulebase.py names them and `twinbot fuzzy` prints them.
"""
from protocol.compat import const

ONE = const(1024)  # membership 1.0
N_SENSORS = const(8)

# Obstacle membership ramp, in reflected ADC counts (12-bit).
NEAR_LO = const(40)
NEAR_HI = const(700)

# Only numbers live here (RAM is scarce on the robot); the names of terms,
# actions and antecedents are in tools/cli/fuzzy.py, in the same order.

# Wheel-speed singletons, % of the max_speed parameter (Figs. 17 and 18).
_FULL_BACK = const(0)
_BACK = const(1)
_SLOW = const(2)
_AHEAD = const(3)
_FAST = const(4)
TERMS = (-100, -80, 15, 55, 100)  # full back, back, slow, ahead, fast

# Actions: (left wheel term, right wheel term).  Turning right means the
# left wheel runs faster than the right.
_GO_AHEAD = const(0)
_GO_BACK = const(1)
_MORE_RIGHT = const(2)
_MORE_LEFT = const(3)
_FAST_AHEAD = const(4)
_QUICK_RIGHT = const(5)
_QUICK_LEFT = const(6)
ACTIONS = (
    (_AHEAD, _AHEAD),  # go ahead
    (_BACK, _BACK),  # go back
    (_FAST, _SLOW),  # go more on right
    (_SLOW, _FAST),  # go more on left
    (_FAST, _FAST),  # go fast ahead
    (_FAST, _FULL_BACK),  # quick turn right
    (_FULL_BACK, _FAST),  # quick turn left
)

# Antecedents: 0..7 "obstacle on S1..S8", 8..11 "obstacle on the front,
# left, back, right" (circular fuzzification), 12 always true.
_FRONT = const(8)
_LEFT = const(9)
_BACKWARD = const(10)
_RIGHT = const(11)
ALWAYS = const(12)

# (antecedent, action), in the paper's order.
RULES_FIRST = (
    (ALWAYS, _GO_AHEAD),
    (_FRONT, _GO_BACK),
    (_LEFT, _MORE_RIGHT),
    (_RIGHT, _MORE_LEFT),
    (_BACKWARD, _FAST_AHEAD),
)
RULES_REFINED = (
    (ALWAYS, _GO_AHEAD),
    (0, _GO_BACK),  # S1 front
    (2, _MORE_RIGHT),  # S3 left
    (6, _MORE_LEFT),  # S7 right
    (4, _FAST_AHEAD),  # S5 back
    (1, _QUICK_RIGHT),  # S2 front-left
    (3, _FAST_AHEAD),  # S4 back-left: fast ahead and more right
    (3, _MORE_RIGHT),
    (5, _FAST_AHEAD),  # S6 back-right: fast ahead and more left
    (5, _MORE_LEFT),
    (7, _QUICK_LEFT),  # S8 front-right
)
RULE_SETS = (RULES_FIRST, RULES_REFINED)
RULE_SET_NAMES = ("first", "refined")  # the rule_set parameter's values, by index


def direction_weight(direction: int, sensor: int) -> int:
    """Membership (0..1024) of sensor's bearing in a direction's circular set.

    direction 0..3 = front, left, back, right at 0, 90, 180, 270 degrees;
    sensor i sits at 45*i degrees; each set is a triangle of half-width 90.
    """
    diff = (45 * sensor - 90 * direction) % 360
    if diff > 180:
        diff = 360 - diff
    if diff >= 90:
        return 0
    return ONE - (diff * ONE) // 90


def membership(reading: int, lo: int = NEAR_LO, hi: int = NEAR_HI) -> int:
    """Obstacle membership of one reflected reading: a ramp from lo to hi."""
    if reading <= lo:
        return 0
    if reading >= hi:
        return ONE
    return ((reading - lo) * ONE) // (hi - lo)


class FuzzyController:
    """Evaluates one rule set; infer() allocates nothing."""

    def __init__(self, rule_set: int = 1, max_speed: int = 200) -> None:
        self.mu = [0] * N_SENSORS  # obstacle membership per sensor
        self.direction_mu = [0] * 4  # front, left, back, right
        self._dirw = [direction_weight(d, i) for d in range(4) for i in range(N_SENSORS)]
        self.lo = NEAR_LO
        self.hi = NEAR_HI
        self.left = 0
        self.right = 0
        self.rule_set = 0
        self.max_speed = 0
        self._sum_l = [0] * (ALWAYS + 1)
        self._sum_r = [0] * (ALWAYS + 1)
        self._count = [0] * (ALWAYS + 1)
        self.configure(rule_set, max_speed)

    def configure(self, rule_set: int, max_speed: int) -> None:
        """Select a rule set and speed scale.

        Rules sharing an antecedent share its firing strength, so their
        singletons are summed once here: per antecedent a, the sums of the
        left and right singletons and the number of rules.  infer() then
        adds w_a * sum instead of one term per rule; the integers are the
        same, in fewer steps.
        """
        if rule_set != 0 and rule_set != 1:
            raise ValueError("rule_set must be 0 (first) or 1 (refined)")
        self.rule_set = rule_set
        self.max_speed = max_speed
        sum_l = self._sum_l  # refilled in place: a PARAM_SET allocates nothing
        sum_r = self._sum_r
        count = self._count
        for a in range(ALWAYS + 1):
            sum_l[a] = 0
            sum_r[a] = 0
            count[a] = 0
        rules = RULE_SETS[rule_set]
        for k in range(len(rules)):
            rule = rules[k]
            antecedent = rule[0]
            action = ACTIONS[rule[1]]
            sum_l[antecedent] += TERMS[action[0]] * max_speed // 100
            sum_r[antecedent] += TERMS[action[1]] * max_speed // 100
            count[antecedent] += 1

    def infer(self, reflected: list[int]) -> None:
        """Set self.left, self.right (mm/s) from the 8 reflected readings."""
        mu = self.mu
        lo = self.lo
        span = self.hi - lo
        sum_l = self._sum_l
        sum_r = self._sum_r
        count = self._count
        num_l = ONE * sum_l[ALWAYS]
        num_r = ONE * sum_r[ALWAYS]
        den = ONE * count[ALWAYS]
        for i in range(N_SENSORS):
            r = reflected[i]
            if r <= lo:
                mu[i] = 0
                continue
            w = ONE if r >= lo + span else ((r - lo) * ONE) // span
            mu[i] = w
            num_l += w * sum_l[i]
            num_r += w * sum_r[i]
            den += w * count[i]
        dmu = self.direction_mu
        if self.rule_set == 0:
            dirw = self._dirw
            for d in range(4):
                best = 0
                base = d * N_SENSORS
                for i in range(N_SENSORS):
                    v = mu[i]
                    w = dirw[base + i]
                    if w < v:
                        v = w
                    if v > best:
                        best = v
                dmu[d] = best
                a = N_SENSORS + d
                num_l += best * sum_l[a]
                num_r += best * sum_r[a]
                den += best * count[a]
        # den >= ONE: the unconditional rule always fires.  Round half up.
        self.left = (2 * num_l + den) // (2 * den)
        self.right = (2 * num_r + den) // (2 * den)
