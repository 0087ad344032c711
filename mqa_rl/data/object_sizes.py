"""Real-world sizes of the 60 object instances, with the product or YCB object each is sized after.

The procedural builders in ``mqa_rl.data.objects`` fix each instance's *shape and proportions*;
``make_object`` then scales the instance uniformly so that its longest side equals the length below.
YCB numbers are from the YCB object set's published dimensions (Calli et al., 2015); product numbers
are typical retail sizes. Density stays per class, so masses grow with the volume to real values
(e.g. a hardcover ~0.6 kg, a claw hammer ~0.5 kg).
"""

from __future__ import annotations

# class -> one (longest side in metres, what it is sized after) per instance
REAL_LENGTH: dict[str, tuple[tuple[float, str], ...]] = {
    "can": ((0.115, "330 ml soda can, Ø 66 × 115 mm"),
            (0.134, "250 ml slim energy-drink can, Ø 53 × 134 mm"),
            (0.101, "400 g food tin, Ø 93 × 101 mm (YCB 002 coffee can is Ø 102 × 139 mm)")),
    "food_box": ((0.210, "YCB 003 cracker box, 210 × 158 × 60 mm"),
                 (0.175, "YCB 004 sugar box, 175 × 89 × 38 mm"),
                 (0.110, "YCB 008 pudding box, 110 × 89 × 35 mm")),
    "book": ((0.175, "mass-market paperback, 175 × 107 × 25 mm"),
             (0.235, "large hardcover, 235 × 168 × 49 mm"),
             (0.148, "A6 notebook, 148 × 105 × 15 mm")),
    "scissors": ((0.200, "YCB 037 scissors, 200 mm"),
                 (0.170, "general-purpose scissors, 170 mm"),
                 (0.130, "children's scissors, 130 mm")),
    "gamepad": ((0.153, "Xbox controller, 153 × 106 × 61 mm"),
                (0.160, "DualShock 4, 160 × 98 × 55 mm"),
                (0.152, "Switch Pro controller, 152 × 106 × 60 mm")),
    "bottle": ((0.205, "500 ml PET water bottle, Ø 65 × 205 mm"),
               (0.190, "YCB 006 mustard bottle, 190 mm"),
               (0.155, "250 ml juice bottle, Ø 60 × 155 mm")),
    "mug": ((0.117, "YCB 025 mug, 117 mm with handle, 82 mm tall"),
            (0.120, "standard 300 ml mug, 120 mm with handle"),
            (0.125, "large 400 ml mug, 125 mm with handle")),
    "bowl": ((0.159, "YCB 024 bowl, Ø 159 × 53 mm"),
             (0.150, "cereal bowl, Ø 150 mm"),
             (0.170, "soup plate, Ø 170 mm")),
    "banana": ((0.195, "YCB 011 banana, ~195 mm"),
               (0.180, "medium banana, 180 mm"),
               (0.150, "small banana, 150 mm")),
    "apple": ((0.075, "YCB 013 apple, Ø 75 mm"),
              (0.070, "Gala apple, Ø 70 mm"),
              (0.085, "large apple, Ø 85 mm")),
    "tennis_ball": ((0.067, "ITF tennis ball, Ø 67 mm"),
                    (0.072, "ITF Stage 3 (red) transition ball, Ø 72 mm"),
                    (0.064, "YCB 056 tennis ball, Ø 64 mm")),
    "marker": ((0.137, "permanent marker, 137 mm"),
               (0.121, "YCB 040 large marker, Ø 18 × 121 mm"),
               (0.130, "whiteboard marker, 130 mm")),
    "remote_control": ((0.200, "TV remote, 200 × 50 × 25 mm"),
                       (0.210, "slim TV remote, 210 mm"),
                       (0.170, "set-top-box remote, 170 mm")),
    "toy_car": ((0.180, "1:24 die-cast car, ~180 mm"),
                (0.140, "toddler push car, 140 mm"),
                (0.120, "1:36 die-cast car, ~120 mm")),
    "screwdriver": ((0.215, "YCB 044 flat screwdriver, Ø 31 × 215 mm"),
                    (0.200, "YCB 043 Phillips screwdriver, 200 mm"),
                    (0.130, "stubby screwdriver, 130 mm")),
    "hammer": ((0.280, "claw hammer, 280 mm (YCB 048 is 330 mm)"),
               (0.250, "ball-pein hammer, 250 mm"),
               (0.200, "stubby hammer, 200 mm")),
    "spoon": ((0.200, "YCB 031 spoon, 202 mm"),
              (0.185, "tablespoon, 185 mm"),
              (0.140, "teaspoon, 140 mm")),
    "sponge": ((0.114, "YCB 026 sponge, 114 × 72 × 14 mm"),
               (0.110, "kitchen sponge, 110 × 70 × 30 mm"),
               (0.095, "scrub sponge, 95 mm")),
    "rubber_duck": ((0.100, "classic rubber duck, 100 mm"),
                    (0.085, "small rubber duck, 85 mm"),
                    (0.120, "large rubber duck, 120 mm")),
    "padlock": ((0.070, "YCB 038 padlock, ~70 mm with shackle"),
                (0.090, "50 mm brass padlock, 90 mm with shackle"),
                (0.065, "40 mm laminated padlock, 65 mm with shackle")),
}
