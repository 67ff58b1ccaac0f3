/*---------------------------------------------------------------------------*\
    fiberform - simulator of early paper forming
    SPDX-License-Identifier: GPL-3.0-or-later
-------------------------------------------------------------------------------
Application
    fiberPimpleFoam

Description
    Transient incompressible solver (PIMPLE) for the suspending fluid of a
    fiber suspension: pimpleFoam on a static mesh plus one explicit momentum
    source, the field fiberSource, which carries the forces of the fibers on
    the fluid in two-way coupling.

        ddt(U) + div(phi U) - div(R) = -grad(p) + fiberSource + fvOptions(U)
        div(U) = 0

    Kinematic units as in every incompressible OpenFOAM solver:
        U           velocity                                [m/s]
        p           pressure / rho                          [m2/s2]
        fiberSource force per unit volume / rho             [m/s2]

    0/fiberSource is optional: when absent the source is zero and the solver
    reproduces pimpleFoam exactly. See docs/coupling/fiberPimpleFoam.md.

    -coupled: two-way coupling with fiberdem (fix fiber/coupling) under one
    mpirun (coupling/layer): one step of interval x fiber step per exchange,
    fiberSource = fiberSource0 + reaction / (rho V); see coupledRun.H and
    docs/coupling/launch.md.

Restrictions
    Static mesh (no dynamicMeshDict motion), no MRF zones. -coupled: serial,
    a uniform axis-aligned blockMesh box, no restart.

\*---------------------------------------------------------------------------*/

#include "fvCFD.H"
#include "singlePhaseTransportModel.H"
#include "turbulentTransportModel.H"
#include "pimpleControl.H"
#include "fvOptions.H"

#include "coupling_layer.h"
#include "exchange_map.h"

#include <cstring>

// * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * //

int main(int argc, char *argv[])
{
    argList::addNote
    (
        "Transient incompressible PIMPLE solver with a fiber momentum source"
        " (fiberSource, m/s^2) for fiber-fluid coupling."
    );

    argList::addBoolOption
    (
        "coupled",
        "two-way coupling with fiberdem under one mpirun (MPMD, serial fluid):"
        " fiberSource gets the fibers' reaction every exchange;"
        " see docs/coupling/launch.md"
    );
    argList::addOption
    (
        "couplingTimeout",
        "s",
        "deadline of each blocking coupling exchange in s (default 300)"
    );

    // Coupled mode: this solver starts MPI itself, before OpenFOAM parses the arguments, and splits
    // MPI_COMM_WORLD by MPI_APPNUM (coupling/layer). Serial OpenFOAM never touches MPI, so Debian's
    // stock libraries work. A parallel fluid needs a rebuilt libPstream
    // (scripts/setup/openfoam-pstream.sh) and is not coupled in this version.
    bool coupled = false, parallel = false;
    for (int i = 1; i < argc; ++i)
    {
        coupled = coupled || std::strcmp(argv[i], "-coupled") == 0;
        parallel = parallel || std::strcmp(argv[i], "-parallel") == 0;
    }
    if (coupled)
    {
        if (parallel)
        {
            std::fprintf
            (
                stderr,
                "fiberPimpleFoam: -coupled runs the fluid serially in this version;"
                " remove -parallel (docs/coupling/launch.md)\n"
            );
            return 2;
        }
        MPI_Init(&argc, &argv);
        fiberform::coupling::start_world();
    }

    #include "postProcess.H"

    #include "addCheckCaseOptions.H"
    #include "setRootCaseLists.H"
    #include "createTime.H"
    #include "createMesh.H"
    #include "createControl.H"
    #include "createTimeControls.H"
    #include "initContinuityErrs.H"
    #include "createFields.H"
    #include "CourantNo.H"
    #include "setInitialDeltaT.H"

    turbulence->validate();

    if (coupled)
    {
        #include "coupledRun.H"
    }
    else
    {
        Info<< "\nStarting time loop\n" << endl;

        while (runTime.run())
        {
            #include "readTimeControls.H"
            #include "CourantNo.H"
            #include "setDeltaT.H"

            ++runTime;

            Info<< "Time = " << runTime.timeName() << nl << endl;

            #include "pimpleStep.H"

            runTime.write();

            runTime.printExecutionTime(Info);
        }
    }

    Info<< "End\n" << endl;

    if (coupled)
    {
        MPI_Finalize();
    }

    return 0;
}


// ************************************************************************* //
