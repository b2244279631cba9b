"""Examples of using the lifter downstream (action recognition on ``skeletons_3d``)."""
