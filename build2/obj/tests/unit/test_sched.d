build2/obj/tests/unit/test_sched.o: tests/unit/test_sched.c \
 master/sched.h
master/sched.h:
